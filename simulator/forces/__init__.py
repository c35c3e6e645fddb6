"""Tip--sample force models (dimensionless; positive = repulsive).

Each model has a NumPy reference (``model(z, zdot, contact)``) and a canonical coefficient
vector for the compiled kernel :func:`simulator.forces._kernel.ts_force`.
"""

from .base import AbstractForceModel
from .dmt import DMT
from .electrostatic import Electrostatic
from .exponential_damping import ExponentialDamping
from .jkr import JKR
from .jkr_hysteretic import HystereticJKR
from .lennard_jones import LennardJones
from .none import NoInteraction
from .sum import ForceSum
from .vdw_sphere import SphereVdW
from .viscoelastic import ViscoelasticDMT

__all__ = [
    "AbstractForceModel",
    "DMT",
    "Electrostatic",
    "ExponentialDamping",
    "ForceSum",
    "HystereticJKR",
    "JKR",
    "LennardJones",
    "NoInteraction",
    "SphereVdW",
    "ViscoelasticDMT",
]
