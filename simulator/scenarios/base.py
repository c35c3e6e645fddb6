"""Scenario base class and shared helpers."""

from __future__ import annotations

import abc
import math

import numpy as np

from ..forces.base import check_range
from ..integrate.base import AbstractIntegrator
from ..integrate.rk4 import RK4
from ..integrate.state import Segment, State
from ..labels import trace_labels
from ..system import System
from .result import SimulationResult

__all__ = ["AbstractScenario", "settle", "sync_contact", "as_result"]

#: settle in chunks of this many samples (bounded memory for long settles)
_CHUNK = 200_000


def sync_contact(system: System, state: State) -> None:
    """After a jump of the rest gap, put the regime on the approach branch where it must be.

    A non-hysteretic model is in contact iff ``z <= a0``; a hysteretic one keeps an existing
    contact unless the jump took the tip beyond the break point.
    """
    th = state.theta
    z = state.gap - state.q.sum(axis=1) - system.excitation.gap_modulation * np.sin(th)
    if not system.force.has_contact:
        state.contact[:] = 0
        return
    a0 = system.force.a0
    brk = system.force.break_indentation
    new = np.where(state.contact == 1, z <= a0 - brk, z <= a0)
    state.contact[:] = new.astype(np.int8)


def settle(system: System, state: State, *, integrator: AbstractIntegrator,
           omega: float | np.ndarray, dt: float, periods: float, progress=None) -> State:
    """Integrate ``periods`` drive periods without recording; return the end state.

    ``omega`` may hold one frequency per trajectory (shape (B,)); the periods are then counted
    at the lowest one.
    """
    n = int(math.ceil(periods * 2.0 * math.pi / (float(np.min(omega)) * dt)))
    while n > 0:
        m = min(n, _CHUNK)
        state = integrator.run(system, state, omega=omega, n_samples=m, dt=dt).end
        n -= m
        if progress is not None:
            progress(m)
    return state


def ramp(system: System, *, integrator: AbstractIntegrator, omega: float, dt: float,
         gap_start: float, gap_end: float, n_samples: int, settle_periods: float, legs: int,
         drift: float = 0.0, record_velocity: bool = False, progress=None) -> list[Segment]:
    """Settle on the free orbit at ``gap_start``, then ramp the rest gap to ``gap_end``
    (approach) and, with ``legs=2``, back (retraction), ``n_samples`` samples per leg.

    ``drift`` (a constant rest-gap rate, e.g. thermal drift) is added to both legs. Returns
    the recorded segments, each starting where the previous one ended.
    """
    if legs not in (1, 2):
        raise ValueError(f"legs must be 1 or 2, got {legs!r}")
    state = State.free_orbit(system, omega=omega, gap=gap_start)
    state = settle(system, state, integrator=integrator, omega=omega, dt=dt,
                   periods=settle_periods, progress=progress)
    rate = (gap_end - gap_start) / (n_samples * dt)
    segs: list[Segment] = []
    for sign in (1.0, -1.0)[:legs]:
        start = state if not segs else segs[-1].end
        segs.append(integrator.run(system, start, omega=omega, n_samples=n_samples, dt=dt,
                                   gap_rate=sign * rate + drift,
                                   record_velocity=record_velocity))
    if progress is not None:
        progress(n_samples * legs)
    return segs


def auto_settle_periods(system: System) -> float:
    """Default settling time: ``2.5 Q_1`` drive periods (transient decays by ~e^-8)."""
    return 2.5 * float(system.cantilever.quality_factors[0])


def as_result(system: System, scenario: str, segs: list[Segment], meta: dict) -> SimulationResult:
    """Concatenate consecutive segments of one trajectory (batch index 0) into a result.

    Labels are computed from the concatenated arrays (each segment keeps its own gap
    programme), with the work integrals accumulated from the first start to the last end.
    """
    q = np.concatenate([s.q[0] for s in segs], axis=-1)
    v = (np.concatenate([s.v[0] for s in segs], axis=-1) if segs[0].v is not None else None)
    force = np.concatenate([s.force[0] for s in segs])
    gap = np.concatenate([s.gap[0] for s in segs])
    phase = np.concatenate([s.phase[0] for s in segs])
    omega = float(segs[0].omega[0])
    lab = trace_labels(q=q, force=force, gap=gap, phase=phase,
                       work=segs[-1].end.work[0] - segs[0].start.work[0], dt=segs[0].dt,
                       omega=omega)
    return SimulationResult(
        system=system, scenario=scenario, dt=segs[0].dt, omega=omega, q=q, force=force,
        gap=gap, rest_gap=np.concatenate([s.rest_gap[0] for s in segs]),
        contact=np.concatenate([s.contact[0] for s in segs]), phase=phase, labels=lab,
        meta=meta, velocity=v)


class AbstractScenario(abc.ABC):
    """A measurement protocol. Subclasses store settings and implement :meth:`run`.

    Common settings: ``samples_per_period`` (sampling rate in samples per drive period, or per
    free-resonance period for sweeps), ``integrator`` (default :class:`RK4` automatic),
    ``record_velocity``, ``settle_periods`` (drive periods integrated before recording;
    ``None``: ``2.5 Q_1``).
    """

    name = "abstract"

    def __init__(self, *, samples_per_period: float = 200.0,
                 integrator: AbstractIntegrator | None = None,
                 record_velocity: bool = False, settle_periods: float | None = None) -> None:
        self.samples_per_period = check_range("samples_per_period", samples_per_period,
                                              low=4.0)
        self.settle_periods = (None if settle_periods is None else
                               check_range("settle_periods", settle_periods, low=0.0))
        self.integrator = integrator if integrator is not None else RK4()
        if not isinstance(self.integrator, AbstractIntegrator):
            raise ValueError("integrator must be an AbstractIntegrator, got "
                             f"{type(self.integrator).__name__}")
        self.record_velocity = bool(record_velocity)

    @property
    def dt(self) -> float:
        """Sample interval (dimensionless): ``2 pi / (omega samples_per_period)``."""
        return 2.0 * math.pi / (self.omega * self.samples_per_period)

    def settle_periods_for(self, system: System) -> float:
        """Settling periods: the setting, or ``2.5 Q_1`` when it is ``None``."""
        return auto_settle_periods(system) if self.settle_periods is None else self.settle_periods

    @abc.abstractmethod
    def run(self, system: System, *, progress=None) -> SimulationResult:
        """Simulate ``system``; ``progress(n)`` (optional) is called with samples done."""

    def total_samples(self, system: System) -> int:
        """Samples integrated in total (settling included), for progress bars."""
        return 0

    def to_dict(self) -> dict:
        d = {k: v for k, v in vars(self).items() if k != "integrator"}
        d["integrator"] = repr(self.integrator)
        d["scenario"] = self.name
        return d
