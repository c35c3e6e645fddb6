"""Lock-in demodulator: first-harmonic amplitude and phase of the deflection, as an instrument.

The deflection is mixed with the drive reference (``cos`` and ``sin`` of the drive phase), each
product is passed through ``order`` identical first-order (RC) low-pass sections, as the
digital lock-ins of commercial AFMs do, and the filtered in-phase / quadrature pair is sampled
at the output interval. For ``x = A cos(theta - phi)`` the outputs are ``A`` and the lag
``phi`` (``pi/2`` on free resonance, ``physics.md`` §1 conventions).

Dimensionless like the rest of the simulator: times in units of ``1/omega0``, the bandwidth in
units of ``f0`` (``bandwidth = B / f0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from .forces.base import check_range

__all__ = ["LockIn", "Demodulated"]


@final
@dataclass(frozen=True)
class Demodulated:
    """Lock-in output samples.

    Attributes
    ----------
    tau : ndarray, shape (m,)
        Output times (dimensionless, ``omega0 t``), measured from the first input sample.
    in_phase, quadrature : ndarray, shape (m,)
        Filtered ``A cos(phi)`` and ``A sin(phi)`` (units of the input).
    index : ndarray of int, shape (m,)
        Index of the input sample each output was taken at.
    """

    tau: NDArray[np.float64]
    in_phase: NDArray[np.float64]
    quadrature: NDArray[np.float64]
    index: NDArray[np.int64]

    @property
    def amplitude(self) -> NDArray[np.float64]:
        """First-harmonic amplitude ``A``, shape (m,) (units of the input)."""
        return np.hypot(self.in_phase, self.quadrature)

    @property
    def phase(self) -> NDArray[np.float64]:
        """Lag ``phi`` of the input behind the reference [rad], shape (m,), in (-pi, pi]."""
        return np.arctan2(self.quadrature, self.in_phase)


@final
class LockIn:
    """Mixer, ``order``-th order low-pass of -3 dB bandwidth ``bandwidth``, output sampler.

    Parameters
    ----------
    bandwidth : float
        -3 dB bandwidth of the whole filter in units of ``f0`` (> 0, < 0.5). Each of the
        ``order`` RC sections has the time constant
        ``tau_c = sqrt(2**(1/order) - 1) / (2 pi bandwidth)`` (dimensionless).
    order : int
        Number of cascaded first-order sections (1 ... 8; 4 = 24 dB/octave).
    output_interval : float
        Time between output samples (dimensionless, > 0); rounded to whole input samples.
    """

    def __init__(self, *, bandwidth: float, order: int = 4, output_interval: float) -> None:
        self.bandwidth = check_range("bandwidth", bandwidth, low=0.0, high=0.5, low_open=True,
                                     high_open=True)
        if not isinstance(order, int | np.integer) or not 1 <= int(order) <= 8:
            raise ValueError(f"order must be an integer in [1, 8], got {order!r}")
        self.order = int(order)
        self.output_interval = check_range("output_interval", output_interval, low=0.0,
                                           low_open=True)

    @property
    def time_constant(self) -> float:
        """Time constant of one RC section (dimensionless)."""
        return math.sqrt(2.0 ** (1.0 / self.order) - 1.0) / (2.0 * math.pi * self.bandwidth)

    def step_response(self, tau: ArrayLike) -> NDArray[np.float64]:
        """Analytic unit-step response of the continuous filter at times ``tau`` >= 0.

        ``1 - exp(-s) sum_{k<n} s**k / k!`` with ``s = tau / tau_c`` (Erlang distribution).
        """
        s = np.maximum(np.asarray(tau, dtype=float), 0.0) / self.time_constant
        term = np.ones_like(s)
        acc = np.zeros_like(s)
        for k in range(self.order):
            if k > 0:
                term = term * s / k
            acc = acc + term
        return 1.0 - np.exp(-s) * acc

    def filter(self, x: ArrayLike, *, dt: float, initial: ArrayLike | None = None
               ) -> NDArray[np.float64]:
        """Apply the low-pass along the last axis.

        Parameters
        ----------
        x : array-like, shape (..., n)
            Input sampled every ``dt`` (dimensionless).
        dt : float
            Sample interval (> 0, small compared with the time constant for the discrete
            sections to follow the continuous filter).
        initial : array-like, shape (...), optional
            Filter state at the start (the input level it has settled on); default ``x[..., 0]``.

        Returns
        -------
        ndarray, shape (..., n)
            Filtered signal. Each section is the exact response of an RC section to an input
            held constant over each sample interval (zero-order hold).
        """
        dt = check_range("dt", dt, low=0.0, low_open=True)
        y = np.asarray(x, dtype=float)
        alpha = -math.expm1(-dt / self.time_constant)
        b, a = np.array([alpha]), np.array([1.0, alpha - 1.0])
        start = y[..., 0] if initial is None else np.asarray(initial, dtype=float)
        for _ in range(self.order):
            # state for a settled section: y[-1] = start, so y[0] = start + alpha(x0 - start)
            zi = (1.0 - alpha) * np.asarray(start)[..., None]
            y, _ = signal.lfilter(b, a, y, axis=-1, zi=zi)
        return y

    def demodulate(self, x: ArrayLike, theta: ArrayLike, *, dt: float) -> Demodulated:
        """Demodulate deflection ``x`` against the reference phase ``theta``.

        Parameters
        ----------
        x : array-like, shape (n,)
            Deflection (any unit) sampled every ``dt``.
        theta : array-like, shape (n,)
            Reference (drive) phase [rad]: the reference is ``cos(theta)``.
        dt : float
            Input sample interval (dimensionless).

        Returns
        -------
        Demodulated
            Outputs every ``output_interval`` (rounded to a whole number of input samples),
            starting one output interval after the first sample. The filter starts settled on
            the mean mixer output of the first reference period.
        """
        x = np.asarray(x, dtype=float)
        theta = np.asarray(theta, dtype=float)
        if x.ndim != 1 or x.shape != theta.shape:
            raise ValueError(f"x and theta must be 1-D of equal length, got {x.shape} and "
                             f"{theta.shape}")
        mixed = 2.0 * np.stack([x * np.cos(theta), x * np.sin(theta)])
        per = _first_period(theta)
        initial = mixed[:, :per].mean(axis=1)
        filt = self.filter(mixed, dt=dt, initial=initial)
        step = max(int(round(self.output_interval / dt)), 1)
        idx = np.arange(step, x.size, step, dtype=np.int64)
        return Demodulated(tau=idx * dt, in_phase=filt[0, idx], quadrature=filt[1, idx],
                           index=idx)

    def to_dict(self) -> dict:
        return {"bandwidth": self.bandwidth, "order": self.order,
                "output_interval": self.output_interval}

    def __repr__(self) -> str:
        return (f"LockIn(bandwidth={self.bandwidth!r}, order={self.order!r}, "
                f"output_interval={self.output_interval!r})")


def _first_period(theta: NDArray[np.float64]) -> int:
    """Number of samples in the first whole reference period (at least 1)."""
    unwrapped = np.unwrap(theta)
    n = int(np.searchsorted(np.abs(unwrapped - unwrapped[0]), 2.0 * math.pi))
    return max(min(n, theta.size), 1)
