"""Diagnosis: what the baseline simulation gets wrong, the cause, the extended model, the gain."""

from .diagnoser import Candidate, Diagnoser, HeldOut, NullCalibration, ObservationResult, Step
from .hypotheses import AbstractHypothesis, default_hypotheses
from .model import DiagnosisModel
from .spec import ModelSpec
from .synthetic import CAUSES, EFFECT_CAUSES

__all__ = ["Diagnoser", "NullCalibration", "Candidate", "Step", "ObservationResult", "HeldOut",
           "DiagnosisModel",
           "ModelSpec", "AbstractHypothesis", "default_hypotheses", "CAUSES", "EFFECT_CAUSES"]
