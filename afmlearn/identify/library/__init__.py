"""AFM function library: candidate tip--sample force terms with exponents as parameters."""

from .afm import AFMLibrary, term_from_dict, term_to_dict
from .base import AbstractTerm, Kind, TermInput
from .contact import ContactIndicator, Indentation, IndentationRate
from .damping import ExponentialDamping, GapRate
from .long_range import InversePower, SphereElectrostatic
from .polynomial import Constant, DeflectionPower

__all__ = [
    "AFMLibrary", "AbstractTerm", "Kind", "TermInput", "term_from_dict", "term_to_dict",
    "Constant", "DeflectionPower", "InversePower", "SphereElectrostatic", "ContactIndicator",
    "Indentation", "IndentationRate", "ExponentialDamping", "GapRate",
]
