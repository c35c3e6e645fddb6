"""Diagnosis hypotheses: one class per cause of design.md section 3, each next to the model
extension it adds (:mod:`afmlearn.diagnose.spec`; ``contact_geometry`` frees a baseline
parameter instead)."""

from .adhesion_hysteresis import AdhesionHysteresis, Neck
from .base import AbstractHypothesis, Context, Parameter
from .contact_geometry import ContactGeometry
from .detector_nonlinearity import DetectorMap, DetectorNonlinearity
from .electrostatic import Electrostatic, ElectrostaticTerm
from .higher_mode import HigherMode, SecondMode
from .long_range_damping import DecayingDamping, LongRangeDamping
from .viscoelastic import Viscoelastic, ViscoelasticTerm

__all__ = ["AbstractHypothesis", "Context", "Parameter", "HigherMode", "Viscoelastic",
           "LongRangeDamping", "ContactGeometry", "AdhesionHysteresis", "Electrostatic",
           "DetectorNonlinearity", "default_hypotheses", "SecondMode", "ViscoelasticTerm",
           "DecayingDamping", "Neck", "ElectrostaticTerm", "DetectorMap"]


def default_hypotheses() -> list[AbstractHypothesis]:
    """Every cause of design.md section 3, in its table order."""
    return [HigherMode(), Viscoelastic(), LongRangeDamping(), ContactGeometry(),
            AdhesionHysteresis(), Electrostatic(), DetectorNonlinearity()]
