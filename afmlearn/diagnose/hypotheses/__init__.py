"""Diagnosis hypotheses: one class per cause of design.md section 3."""

from .adhesion_hysteresis import AdhesionHysteresis
from .base import AbstractHypothesis, Context, Parameter
from .contact_geometry import ContactGeometry
from .detector_nonlinearity import DetectorNonlinearity
from .electrostatic import Electrostatic
from .higher_mode import HigherMode
from .long_range_damping import LongRangeDamping
from .viscoelastic import Viscoelastic

__all__ = ["AbstractHypothesis", "Context", "Parameter", "HigherMode", "Viscoelastic",
           "LongRangeDamping", "ContactGeometry", "AdhesionHysteresis", "Electrostatic",
           "DetectorNonlinearity", "default_hypotheses"]


def default_hypotheses() -> list[AbstractHypothesis]:
    """Every cause of design.md section 3, in its table order."""
    return [HigherMode(), Viscoelastic(), LongRangeDamping(), ContactGeometry(),
            AdhesionHysteresis(), Electrostatic(), DetectorNonlinearity()]
