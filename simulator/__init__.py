"""afmlearn's physics simulator: labelled synthetic dynamic-AFM deflection.

numpy / scipy / numba only. Dimensionless inside (``tau = omega0 t``, lengths / rest gap,
forces / ``k L_ref``); :class:`Scales` converts at the edges. See ``physics.md``.
"""

from ._scales import Scales
from .cantilever import Cantilever
from .excitation import AbstractExcitation, BaseExcitation, TipExcitation
from .integrate import RK4, AbstractIntegrator, Segment, State
from .scenarios import Approach, SimulationResult, SteadyState, Sweep, Transient
from .sensor import SensorChain
from .system import System

__all__ = [
    "Approach",
    "SensorChain",
    "SimulationResult",
    "SteadyState",
    "Sweep",
    "Transient",
    "AbstractExcitation",
    "AbstractIntegrator",
    "BaseExcitation",
    "Cantilever",
    "RK4",
    "Scales",
    "Segment",
    "State",
    "System",
    "TipExcitation",
]
