"""Transient: a step in topography under a settled tapping tip."""

from __future__ import annotations

import math
from typing import final

from ..forces.base import check_range
from ..integrate.state import State
from ..system import System
from .base import AbstractScenario, as_result, settle, sync_contact
from .result import SimulationResult

__all__ = ["Transient"]


@final
class Transient(AbstractScenario):
    """Settle at ``gap``, record ``periods_before``, step the rest gap by ``step``, record on.

    Parameters
    ----------
    omega : float
        Drive frequency (> 0).
    gap : float
        Rest gap before the step.
    step : float
        Change of the rest gap (negative: the surface rises towards the tip); the gap after
        the step must stay > 0.
    periods_before, periods_after : float
        Recorded periods before and after the step.
    settle_periods : float or None
        As :class:`SteadyState`.
    """

    name = "transient"

    def __init__(self, *, omega: float = 1.0, gap: float = 1.0, step: float = -0.2,
                 periods_before: float = 20.0, periods_after: float = 200.0,
                 **kwargs) -> None:
        super().__init__(**kwargs)
        self.omega = check_range("omega", omega, low=0.0, low_open=True)
        self.gap = check_range("gap", gap, low=0.0, low_open=True)
        self.step = check_range("step", step, low=-self.gap, high=math.inf, low_open=True)
        self.periods_before = check_range("periods_before", periods_before, low=0.0)
        self.periods_after = check_range("periods_after", periods_after, low=0.0, low_open=True)

    def total_samples(self, system: System) -> int:
        sp = self.settle_periods_for(system)
        return int(math.ceil((sp + self.periods_before + self.periods_after)
                             * self.samples_per_period))

    def run(self, system: System, *, progress=None) -> SimulationResult:
        sp = self.settle_periods_for(system)
        state = State.free_orbit(system, omega=self.omega, gap=self.gap)
        state = settle(system, state, integrator=self.integrator, omega=self.omega, dt=self.dt,
                       periods=sp, progress=progress)
        segs = []
        n1 = int(round(self.periods_before * self.samples_per_period))
        if n1 > 0:
            segs.append(self.integrator.run(system, state, omega=self.omega, n_samples=n1,
                                            dt=self.dt, record_velocity=self.record_velocity))
            state = segs[-1].end.copy()
        state.gap[:] = state.gap + self.step
        sync_contact(system, state)
        n2 = int(round(self.periods_after * self.samples_per_period))
        segs.append(self.integrator.run(system, state, omega=self.omega, n_samples=n2,
                                        dt=self.dt, record_velocity=self.record_velocity))
        if progress is not None:
            progress(n1 + n2)
        meta = self.to_dict()
        meta["step_index"] = n1
        return as_result(system, self.name, segs, meta)
