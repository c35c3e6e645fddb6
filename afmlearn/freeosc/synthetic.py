"""Synthetic free oscillations with a known cause of harmonics (for tests and benchmarks).

A linear one-mode lever, ``x'' + x'/Q + x = f(tau)`` (``tau = omega0 t``, lengths in units of
the mean amplitude), driven on resonance with a slowly modulated amplitude (a stand-in for a
self-oscillation whose amplitude wanders: the lever arm that separates ``A^n`` scaling from a
fixed drive), optionally with an electrostatic force at ``2 Omega`` of fixed amplitude (an ac
bias at the oscillation frequency, ``F ~ V_ac^2 cos(2 Omega tau + theta)``), solved exactly
for piecewise-constant forcing (zero-order-hold discretisation on an 8x finer grid, each
step holding the forcing's midpoint value, then decimated; checked against an adaptive ODE
integration in the tests). The measurement is `simulator.SensorChain` (e.g.
`DetectorNonlinearity`, `GaussianNoise`, `Quantizer`). The simulator's force models have no
ac bias, hence this linear solver here; a linear lever needs no nonlinear integrator.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from simulator.sensor import SensorChain

__all__ = ["simulate_free"]

#: oversampling of the forcing before decimation
_OVERSAMPLE = 8


def simulate_free(*, n_periods: int = 4000, samples_per_period: float = 19.0,
                  quality_factor: float = 200.0, modulation_depth: float = 0.15,
                  modulation_periods: float = 1500.0, ac_force: float = 0.0,
                  ac_phase_rad: float = 0.3, sensor: SensorChain | None = None
                  ) -> tuple[NDArray[np.float64], float]:
    """Measured record of a freely oscillating linear lever (mean amplitude 1).

    Parameters
    ----------
    n_periods : int, default 4000
        Length in oscillation periods, >= 50.
    samples_per_period : float, default 19
        Sampling rate / oscillation frequency, > 2.
    quality_factor : float, default 200
        Q > 0.5.
    modulation_depth : float, default 0.15
        Relative amplitude modulation of the drive, in [0, 0.9] (slow sinusoid).
    modulation_periods : float, default 1500
        Its period in oscillation periods, > 2 Q / (2 pi) (slower than the lever's ring time).
    ac_force : float, default 0
        Amplitude of the 2 Omega force in units of ``k x`` mean amplitude, >= 0.
    ac_phase_rad : float, default 0.3
        Its phase relative to twice the drive's phase [rad].
    sensor : simulator.SensorChain, optional
        The measurement (default: perfect).

    Returns
    -------
    y : ndarray, shape (round(n_periods * samples_per_period),)
        Measured record (units of the mean amplitude).
    sample_rate : float
        Samples per unit of ``f0`` (sampling rate / resonance frequency).
    """
    if n_periods < 50:
        raise ValueError(f"n_periods must be >= 50, got {n_periods!r}")
    if not samples_per_period > 2:
        raise ValueError(f"samples_per_period must be > 2, got {samples_per_period!r}")
    if not quality_factor > 0.5:
        raise ValueError(f"quality_factor must be > 0.5, got {quality_factor!r}")
    if not 0.0 <= modulation_depth <= 0.9:
        raise ValueError(f"modulation_depth must lie in [0, 0.9], got {modulation_depth!r}")
    if not modulation_periods > quality_factor / math.pi:
        raise ValueError(f"modulation_periods must exceed Q / pi = "
                         f"{quality_factor / math.pi:g}, got {modulation_periods!r}")
    if not ac_force >= 0:
        raise ValueError(f"ac_force must be >= 0, got {ac_force!r}")
    n = int(round(n_periods * samples_per_period))
    dtau = 2 * math.pi / samples_per_period / _OVERSAMPLE
    tau = np.arange(n * _OVERSAMPLE) * dtau
    mid = tau + dtau / 2  # the held value of each step at its midpoint: 2nd-order accurate
    envelope = 1.0 + modulation_depth * np.sin(mid / modulation_periods)
    force = envelope / quality_factor * np.sin(mid)  # on resonance: x ~ envelope * -cos(tau)
    force += ac_force * np.cos(2 * mid + ac_phase_rad)
    num_d, den_d, _ = signal.cont2discrete(([1.0], [1.0, 1.0 / quality_factor, 1.0]), dtau,
                                           method="zoh")
    # start on the steady orbit of the mean drive: x(0) = -1, x'(0) = 0 (transient avoided)
    x = signal.lfilter(np.ravel(num_d), den_d, force)
    wd = math.sqrt(1.0 - 1.0 / (4 * quality_factor**2))  # homogeneous part: x(0) = -1, x'(0) = 0
    free = -np.exp(-tau / (2 * quality_factor)) * (
        np.cos(wd * tau) + np.sin(wd * tau) / (2 * quality_factor * wd))
    x = (x + free)[::_OVERSAMPLE]
    chain = sensor if sensor is not None else SensorChain([])
    y = chain(x, x_ref=1.0, dt=2 * math.pi / samples_per_period)
    return np.asarray(y, dtype=float), float(samples_per_period)
