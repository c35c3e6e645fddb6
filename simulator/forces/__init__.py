"""Tip--sample force models (dimensionless; positive = repulsive).

Each model has a NumPy reference (``model(z, zdot, contact)``) and its terms in the one
force-law representation (:class:`ForceLaw`, ``model.law()``) that the compiled evaluator
:func:`simulator.forces._kernel.law_force` and the integrator kernel read.
"""

from .base import AbstractForceModel, ForceSum
from .dmt import DMT
from .electrostatic import Electrostatic
from .exponential_damping import ExponentialDamping
from .jkr import JKR
from .jkr_hysteretic import HystereticJKR
from .law import ForceLaw, Kind, Term
from .lennard_jones import LennardJones
from .none import NoInteraction
from .vdw_sphere import SphereVdW
from .viscoelastic import ViscoelasticDMT

__all__ = [
    "AbstractForceModel",
    "DMT",
    "Electrostatic",
    "ExponentialDamping",
    "ForceLaw",
    "ForceSum",
    "HystereticJKR",
    "JKR",
    "Kind",
    "LennardJones",
    "NoInteraction",
    "SphereVdW",
    "Term",
    "ViscoelasticDMT",
]
