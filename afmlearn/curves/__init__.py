"""Analysis of AM-AFM lock-in curves (amplitude and phase versus distance) alone.

A slow-flow (Krylov--Bogoliubov averaged) forward model of the single-mode lever along the
ramp, passed through the recording lock-in's filter (:class:`SlowFlowModel`); one tip--sample
law fitted to the approach (:class:`CurveFitter`); causes named by evidence with the gain
measured on the retraction (:class:`CurveDiagnoser`); energy dissipated per cycle
(:func:`dissipated_energy`).
"""

from .curve import Curve
from .diagnose import CurveDiagnoser, equation, heldout_nrmse
from .dissipation import dissipated_energy
from .fit import CurveFitter
from .hypotheses import BASELINE, EXTENSIONS, Hypothesis, Parameter
from .law import CurveLaw
from .model import SlowFlowModel, drive_from_free

__all__ = ["BASELINE", "EXTENSIONS", "Curve", "CurveDiagnoser", "CurveFitter", "CurveLaw",
           "Hypothesis", "Parameter", "SlowFlowModel", "dissipated_energy", "drive_from_free",
           "equation", "heldout_nrmse"]
