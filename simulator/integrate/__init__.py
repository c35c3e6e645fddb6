"""Integrators (strategies as objects) and their state/segment records."""

from .base import AbstractIntegrator
from .rk4 import RK4
from .scipy_ref import SolveIVP
from .state import Segment, State

__all__ = ["AbstractIntegrator", "RK4", "SolveIVP", "Segment", "State"]
