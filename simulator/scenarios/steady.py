"""Steady state at a fixed gap, reached as an approach from far away would reach it."""

from __future__ import annotations

import math
from typing import final

from ..forces.base import check_range
from ..integrate.state import State
from ..system import System
from .base import AbstractScenario, as_result, settle
from .result import SimulationResult

__all__ = ["SteadyState"]


@final
class SteadyState(AbstractScenario):
    """Start on the free orbit at the rest gap, settle, then record.

    Starting on the free (large-amplitude) orbit selects the branch an approach from far away
    reaches, i.e. the repulsive (tapping) branch when the free amplitude exceeds the gap.

    Parameters
    ----------
    omega : float
        Drive frequency ``Omega = f / f0`` (> 0).
    gap : float
        Rest gap in units of ``L_ref`` (default 1).
    n_periods : float
        Recorded drive periods (> 0).
    settle_periods : float or None
        Periods integrated before recording; ``None``: ``2.5 Q_1``.
    samples_per_period, integrator, record_velocity :
        See :class:`AbstractScenario`.
    """

    name = "steady"

    def __init__(self, *, omega: float = 1.0, gap: float = 1.0, n_periods: float = 100.0,
                 **kwargs) -> None:
        super().__init__(**kwargs)
        self.omega = check_range("omega", omega, low=0.0, low_open=True)
        self.gap = check_range("gap", gap, low=0.0, low_open=True)
        self.n_periods = check_range("n_periods", n_periods, low=0.0, low_open=True)

    def total_samples(self, system: System) -> int:
        return int(math.ceil((self.settle_periods_for(system) + self.n_periods)
                             * self.samples_per_period))

    def run(self, system: System, *, progress=None) -> SimulationResult:
        state = State.free_orbit(system, omega=self.omega, gap=self.gap)
        state = settle(system, state, integrator=self.integrator, omega=self.omega, dt=self.dt,
                       periods=self.settle_periods_for(system), progress=progress)
        n = int(round(self.n_periods * self.samples_per_period))
        seg = self.integrator.run(system, state, omega=self.omega, n_samples=n, dt=self.dt,
                                  record_velocity=self.record_velocity)
        if progress is not None:
            progress(n)
        return as_result(system, self.name, [seg], self.to_dict())
