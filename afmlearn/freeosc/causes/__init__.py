"""Causes of harmonics in a free oscillation (each a linear extension of the baseline)."""

from afmlearn.freeosc.causes.base import AbstractCause
from afmlearn.freeosc.causes.baseline import LinearLever
from afmlearn.freeosc.causes.detector import DetectorNonlinearity
from afmlearn.freeosc.causes.duffing import DuffingStiffness
from afmlearn.freeosc.causes.electrostatic import AcBiasDrive, GapModulatedForce, transfer
from afmlearn.freeosc.causes.higher_mode import HigherMode
from afmlearn.freeosc.causes.quantisation import Quantisation

__all__ = ["AbstractCause", "AcBiasDrive", "DetectorNonlinearity", "DuffingStiffness",
           "GapModulatedForce", "HigherMode", "LinearLever", "Quantisation", "transfer"]
