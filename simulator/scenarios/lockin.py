"""Lock-in amplitude/phase-versus-distance curve (AM-AFM approach--retract, as recorded).

The piezo ramps the rest gap towards the sample and back (the approach scenario's
integration), the deflection is demodulated at the drive frequency by a :class:`LockIn`, and
amplitude, phase, piezo position and segment are sampled at the lock-in's output rate. Optional
measurement noise (relative amplitude noise, phase noise) and a linear drift of the sample
relative to the piezo (the true rest gap drifts away from the programmed one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

from ..forces.base import check_range
from ..lockin import LockIn
from ..system import System
from .base import AbstractScenario, as_result, ramp
from .result import SimulationResult

__all__ = ["LockInCurve", "CurveRecord"]


@final
@dataclass(frozen=True)
class CurveRecord:
    """What the instrument records (dimensionless: lengths / ``L_ref``, time ``omega0 t``).

    Attributes
    ----------
    tau : ndarray, shape (m,)
        Output times from the start of the approach.
    amplitude : ndarray, shape (m,)
        First-harmonic amplitude of the deflection.
    phase : ndarray, shape (m,)
        Lag of the deflection behind the drive [rad] (``pi/2`` on free resonance).
    z_piezo : ndarray, shape (m,)
        Programmed rest gap (piezo position, larger = further from the sample).
    segment : ndarray of int8, shape (m,)
        0 approach, 1 retraction.
    rest_gap : ndarray, shape (m,)
        True rest gap (``z_piezo`` plus drift): truth, for labels only.
    free_amplitude : float
        Amplitude of the linear free orbit at the drive (noise-free).
    """

    tau: NDArray[np.float64]
    amplitude: NDArray[np.float64]
    phase: NDArray[np.float64]
    z_piezo: NDArray[np.float64]
    segment: NDArray[np.int8]
    rest_gap: NDArray[np.float64]
    free_amplitude: float


@final
class LockInCurve(AbstractScenario):
    """Settle far away, ramp the rest gap to ``gap_end`` and back, demodulate with a lock-in.

    Parameters
    ----------
    omega : float
        Drive frequency (> 0).
    gap_start, gap_end : float
        Rest gap at the start (far) and at the turning point (> 0).
    n_periods : float
        Duration of each ramp (approach, retraction) in drive periods.
    lockin : LockIn
        The demodulator (bandwidth, order, output interval).
    amplitude_noise : float
        Standard deviation of Gaussian noise on the amplitude, relative to the free amplitude
        (0 ... 0.5; 0.01 = 1 %).
    phase_noise : float
        Standard deviation of Gaussian noise on the phase [rad] (0 ... 0.5).
    drift : float
        Rate of the true rest gap relative to the programmed one (``L_ref`` per unit
        ``tau``), e.g. thermal drift of the sample; 0 = none.
    seed : int
        Seed of the measurement noise.
    samples_per_period, integrator, record_velocity, settle_periods
        As :class:`AbstractScenario`.
    """

    name = "lockin"

    def __init__(self, *, omega: float = 1.0, gap_start: float = 2.0, gap_end: float = 0.5,
                 n_periods: float = 2000.0, lockin: LockIn | None = None,
                 amplitude_noise: float = 0.0, phase_noise: float = 0.0, drift: float = 0.0,
                 seed: int = 0, **kwargs) -> None:
        super().__init__(**kwargs)
        self.omega = check_range("omega", omega, low=0.0, low_open=True)
        self.gap_start = check_range("gap_start", gap_start, low=0.0, low_open=True)
        self.gap_end = check_range("gap_end", gap_end, low=0.0, low_open=True)
        self.n_periods = check_range("n_periods", n_periods, low=1.0)
        if lockin is None:
            lockin = LockIn(bandwidth=0.01, order=4, output_interval=20.0 * 2.0 * math.pi)
        if not isinstance(lockin, LockIn):
            raise ValueError(f"lockin must be a LockIn, got {type(lockin).__name__}")
        self.lockin = lockin
        self.amplitude_noise = check_range("amplitude_noise", amplitude_noise, low=0.0,
                                           high=0.5)
        self.phase_noise = check_range("phase_noise", phase_noise, low=0.0, high=0.5)
        self.drift = check_range("drift", drift, low=-1.0, high=1.0)
        if not isinstance(seed, int | np.integer) or seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
        self.seed = int(seed)

    def total_samples(self, system: System) -> int:
        sp = self.settle_periods_for(system)
        return int(math.ceil((sp + 2.0 * self.n_periods) * self.samples_per_period))

    def run(self, system: System, *, progress=None) -> SimulationResult:
        """The time-domain ramp; ``meta["curve"]`` holds the :class:`CurveRecord`."""
        n = int(round(self.n_periods * self.samples_per_period))
        segs = ramp(system, integrator=self.integrator, omega=self.omega, dt=self.dt,
                    gap_start=self.gap_start, gap_end=self.gap_end, n_samples=n,
                    settle_periods=self.settle_periods_for(system), legs=2, drift=self.drift,
                    record_velocity=self.record_velocity, progress=progress)
        meta = self.to_dict()
        result = as_result(system, self.name, segs, meta)
        meta["curve"] = self.record(system, result)
        return result

    def record(self, system: System, result: SimulationResult) -> CurveRecord:
        """Demodulate a ramp's deflection and add the measurement noise (seeded)."""
        # the drive is cos(theta) on the tip, sin(theta) = cos(theta - pi/2) for a base drive
        ref = result.phase - (0.5 * math.pi if system.excitation.kind == "base" else 0.0)
        out = self.lockin.demodulate(result.deflection, ref, dt=result.dt)
        n = result.q.shape[-1] // 2
        free = system.excitation.free_amplitude(system.cantilever, self.omega)
        rng = np.random.default_rng(self.seed)
        amp = out.amplitude + self.amplitude_noise * free * rng.standard_normal(out.tau.size)
        phase = out.phase + self.phase_noise * rng.standard_normal(out.tau.size)
        # programmed piezo position: the ramp without the drift
        tau = out.tau
        t_turn = n * result.dt
        z_piezo = np.where(tau < t_turn,
                           self.gap_start + (self.gap_end - self.gap_start) * tau / t_turn,
                           self.gap_end + (self.gap_start - self.gap_end) * (tau - t_turn)
                           / t_turn)
        return CurveRecord(tau=tau, amplitude=amp, phase=phase, z_piezo=z_piezo,
                           segment=(out.index >= n).astype(np.int8),
                           rest_gap=result.rest_gap[out.index], free_amplitude=float(free))

    def to_dict(self) -> dict:
        d = super().to_dict()
        d["lockin"] = self.lockin.to_dict()
        return d
