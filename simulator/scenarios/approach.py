"""Approach (and optional retract) ramp: the rest gap varies in time (dynamic spectroscopy)."""

from __future__ import annotations

import dataclasses
import math
from typing import final

import numpy as np

from ..forces.base import check_range
from ..system import System
from .base import AbstractScenario, as_result, ramp
from .result import SimulationResult

__all__ = ["Approach"]


@final
class Approach(AbstractScenario):
    """Settle at ``gap_start`` (far away), then ramp the rest gap linearly to ``gap_end``.

    Parameters
    ----------
    omega : float
        Drive frequency (> 0).
    gap_start, gap_end : float
        Rest gap at the start and end of the ramp (> 0).
    n_periods : float
        Duration of the ramp in drive periods (the ramp must be slow compared with ``Q``
        periods for a quasi-static amplitude--distance curve).
    retract : bool
        Append the reverse ramp (approach--retract cycle); the result's ``segment`` marks
        the samples of each ramp (0 approach, 1 retraction).
    settle_periods : float or None
        As :class:`SteadyState`.
    """

    name = "approach"

    def __init__(self, *, omega: float = 1.0, gap_start: float = 2.0, gap_end: float = 0.5,
                 n_periods: float = 2000.0, retract: bool = False,
                 **kwargs) -> None:
        super().__init__(**kwargs)
        self.omega = check_range("omega", omega, low=0.0, low_open=True)
        self.gap_start = check_range("gap_start", gap_start, low=0.0, low_open=True)
        self.gap_end = check_range("gap_end", gap_end, low=0.0, low_open=True)
        self.n_periods = check_range("n_periods", n_periods, low=0.0, low_open=True)
        self.retract = bool(retract)

    def total_samples(self, system: System) -> int:
        sp = self.settle_periods_for(system)
        ramps = 2 if self.retract else 1
        return int(math.ceil((sp + ramps * self.n_periods) * self.samples_per_period))

    def run(self, system: System, *, progress=None) -> SimulationResult:
        n = int(round(self.n_periods * self.samples_per_period))
        segs = ramp(system, integrator=self.integrator, omega=self.omega, dt=self.dt,
                    gap_start=self.gap_start, gap_end=self.gap_end, n_samples=n,
                    settle_periods=self.settle_periods_for(system),
                    legs=2 if self.retract else 1, record_velocity=self.record_velocity,
                    progress=progress)
        result = as_result(system, self.name, segs, self.to_dict())
        segment = np.repeat(np.arange(len(segs), dtype=np.int8), n)
        return dataclasses.replace(result, segment=segment)
