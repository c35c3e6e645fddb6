"""Measurement scenarios: steady state, transient step, approach ramp, frequency sweep,
dynamic spectroscopy (steady records at several rest gaps), lock-in curves."""

from .approach import Approach
from .base import AbstractScenario
from .lockin import CurveRecord, LockInCurve
from .result import SimulationResult
from .spectroscopy import Spectroscopy
from .steady import SteadyState
from .sweep import Sweep, SweepPoint
from .transient import Transient

__all__ = ["AbstractScenario", "Approach", "CurveRecord", "LockInCurve", "SimulationResult",
           "Spectroscopy", "SteadyState", "Sweep", "SweepPoint", "Transient"]
