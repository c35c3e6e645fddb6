"""Diagnosis of free, contact-less oscillation records (e.g. a self-oscillating KPFM lever).

`diagnose_free` names the cause of a free oscillation's harmonics (detector nonlinearity, an
electrostatic force, a higher mode, a nonlinear stiffness, quantisation) with a held-out
gain over a linear one-mode lever; `demodulate` and `track_harmonics` give the fundamental's
state and the per-block harmonics; `simulate_free` makes synthetic records with known truth.
"""

from afmlearn.freeosc.demodulate import Demodulation, demodulate
from afmlearn.freeosc.diagnose import FreeOscillationDiagnosis, default_causes, diagnose_free
from afmlearn.freeosc.synthetic import simulate_free
from afmlearn.freeosc.track import HarmonicTrack, track_harmonics

__all__ = ["Demodulation", "FreeOscillationDiagnosis", "HarmonicTrack", "default_causes",
           "demodulate", "diagnose_free", "simulate_free", "track_harmonics"]
