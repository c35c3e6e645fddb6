"""Measurement scenarios: steady state, transient step, approach ramp, frequency sweep."""

from .approach import Approach
from .base import AbstractScenario
from .result import SimulationResult
from .steady import SteadyState
from .sweep import Sweep, SweepPoint
from .transient import Transient

__all__ = ["AbstractScenario", "Approach", "SimulationResult", "SteadyState", "Sweep",
           "SweepPoint", "Transient"]
