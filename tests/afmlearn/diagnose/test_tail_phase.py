"""One record's held-out tail: every model is scored at the recorded drive phase, else at the
one that fits the tail.

Without a recorded drive phase the phase is a nuisance, not a prediction: the held-out NRMSE
of each model must be its minimum over that one number (as for a held-out set-point). The
phase the output-error fit projected out is optimal for the fit's whitened harmonics, not for
the NRMSE; scoring the tail at it penalised a right extension by its harmonic weighting (an
electrostatic draw at 1,000 samples/period: gain 0.40 -> 0.03).
"""

from __future__ import annotations

import numpy as np

from afmlearn.diagnose import Diagnoser
from afmlearn.io import read_trace
from afmlearn.metrics import nrmse
from afmlearn.preprocess import fit_harmonics


def _shifted(tau: np.ndarray, y: np.ndarray, omega: float, n_h: int, delta: float
             ) -> np.ndarray:
    """``y`` (periodic in ``omega``) delayed by the drive phase ``delta`` [rad]."""
    X = fit_harmonics(tau, y, omega, n_harmonics=n_h).complex_amplitudes
    n = np.arange(X.size)
    return np.real(np.exp(1j * np.outer(omega * tau, n)) @ (X * np.exp(-1j * n * delta)))


def test_each_model_is_scored_at_the_phase_that_fits_the_tail(make_trace):
    path, _ = make_trace("electrostatic", 5, spp=200, noise=0.005)
    d = Diagnoser(all_gains=True).fit(read_trace(path))
    assert d.design_ == "tail"
    held, omega = d.heldout_, d.calibrated_.omega
    n_h = d.orbit_.n_h
    keys = [k for k in held.simulated if k != "extended"
            and np.all(np.isfinite(held.simulated[k]))]
    assert "none" in keys and len(keys) >= 3
    for key in keys:
        y = held.simulated[key]
        at = nrmse(_shifted(held.tau, y, omega, n_h, 0.0), held.reference)
        # the series of the prediction is the prediction (a 2,048-phase orbit, resampled)
        assert abs(at - nrmse(y, held.reference)) < 0.02 * at
        for delta in (-1e-3, -2e-4, -5e-5, 5e-5, 2e-4, 1e-3):
            shifted = nrmse(_shifted(held.tau, y, omega, n_h, delta), held.reference)
            assert shifted > at * (1 - 1e-3), (key, delta, at, shifted)


def test_a_recorded_phase_is_the_one_the_tail_is_predicted_at(make_series):
    """One row of a series with its drive phase recorded: every model's tail is predicted at
    that phase (model convention ``B cos(Omega tau - phi)``, ``phi = -drive_phase_rad``),
    none aligned on the data it is scored against."""
    path, _ = make_series("viscoelastic+detector_nonlinearity", 7)
    trace = read_trace(path)
    d = Diagnoser(all_gains=True).fit(trace, row=1)
    assert d.design_ == "tail"
    recorded = -float(trace.row(1).drive_phase_rad)
    phases = d.heldout_.phase
    assert "none" in phases and len(phases) >= 2
    for key, phi in phases.items():
        assert abs(np.angle(np.exp(1j * (phi - recorded)))) < 1e-9, (key, phi, recorded)
