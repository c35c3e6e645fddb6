"""Harmonic-balance algebra and its noise model (whitened residual ~ chi-square)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from afmlearn.diagnose.balance import (
    HarmonicBalance,
    PeriodicOrbit,
    Solution,
    bounded_lstsq,
    from_real,
    harmonics,
    synthesize,
    to_real,
)
from afmlearn.diagnose.hypotheses.detector_nonlinearity import DetectorMap
from afmlearn.diagnose.joint import JointBalance
from afmlearn.diagnose.output_error import OutputError
from afmlearn.diagnose.spec import ModelSpec, invert_polynomial
from afmlearn.io import read_trace
from afmlearn.preprocess import calibrate, fit_harmonics


def test_harmonics_roundtrip_and_derivative():
    m = 512
    th = 2 * np.pi * np.arange(m) / m
    u = 0.3 + np.cos(th) - 0.2 * np.sin(3 * th)
    U = harmonics(u, 5)
    assert U[0] == pytest.approx(0.3)
    assert U[1] == pytest.approx(1.0)
    assert U[3] == pytest.approx(0.2j)
    assert np.allclose(synthesize(U, m), u)
    du = -np.sin(th) * 2.0 - 0.2 * 3 * np.cos(3 * th) * 2.0
    assert np.allclose(synthesize(U, m, 1, omega=2.0), du)
    r = to_real(U)
    assert np.allclose(from_real(r), U)


def test_bounded_lstsq_known_answer_and_non_finite_rows_rejected():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 3))
    c = np.array([1.0, -0.5, 2.0])
    P, t = np.zeros((1, 3)), np.zeros(1)
    lo, hi = np.full(3, -np.inf), np.array([np.inf, 0.0, np.inf])
    coef, r = bounded_lstsq(A, A @ c, P, t, lo, hi)
    assert np.allclose(coef, c) and np.allclose(r, 0.0, atol=1e-9)
    # the bound is active: -0.5 is allowed, +0.5 is clipped to 0
    coef, _ = bounded_lstsq(A, A @ np.array([1.0, 0.5, 2.0]), P, t, lo, hi)
    assert coef[1] == pytest.approx(0.0, abs=1e-12)
    # a non-finite column (LAPACK raised "SVD did not converge") is a rejected structure
    A[5, 1] = np.inf
    coef, r = bounded_lstsq(A, A @ c, P, t, lo, hi)
    assert np.all(np.isnan(coef)) and np.all(np.isinf(r)) and r.size == 41


def test_detector_inverse():
    x = np.linspace(-1.5, 1.5, 101)
    y = x + 0.03 * x**2 - 0.01 * x**3
    det = DetectorMap(b2=0.03, b3=-0.01)
    assert np.allclose(det.measure(x), y, rtol=0, atol=1e-15)
    assert np.allclose(det.invert(y), x, rtol=0, atol=1e-12)
    assert np.allclose(invert_polynomial(y + 0.002 * x**4, (0.03, -0.01, 0.002)), x, rtol=0,
                       atol=1e-12)


def test_whitened_chi2_is_chi_square_at_the_truth(make_trace):
    """At the generating model the whitened residual is the orbit noise: chi2 ~ rows."""
    path, case = make_trace("none", 3, spp=200, periods=200)
    tr = read_trace(path, labels=True)
    cal = calibrate(tr)
    n = int(140 * cal.samples_per_period)
    hf = fit_harmonics(cal.tau[:n], cal.x[:n], cal.omega, n_harmonics=20)
    orbit = PeriodicOrbit(hf, gap=1.0, quality_factor=cal.quality_factor,
                          drive_amplitude=cal.drive_amplitude)
    hb = HarmonicBalance(orbit)
    p = tr.labels.model["force"]["parameters"]
    # the true law in the diagnosis library; the drive phase is searched (not recorded)
    best = min((hb.solve(ModelSpec(a0=p["a0"], drive_phase=ph)) for ph in
                np.linspace(-np.pi, np.pi, 721)), key=lambda s: s.chi2)
    hb.set_whitening(best)
    best = min((hb.solve(best.spec.replace(drive_phase=ph)) for ph in
                best.spec.drive_phase + np.linspace(-0.02, 0.02, 81)), key=lambda s: s.chi2)
    rows = 2 * orbit.n_h + 1
    # chi-square with ~rows - 6 degrees of freedom: mean rows - 6, sd sqrt(2 rows)
    assert abs(best.chi2 - (rows - 6)) < 4 * np.sqrt(2 * rows)
    # output error (the model's own orbit against the measured harmonics): at the true force
    # law, with only the lever's phase (projected out in closed form), damping and drive
    # refitted, chi2 is chi-square too, and the refined fit is no worse than the truth.
    # (Coefficients are not asserted: at 1 % noise the van der Waals coefficient and the
    # contact stiffness trade off within noise.)
    oe = OutputError(JointBalance([hb], [None]), cal.scales)
    a0 = p["a0"]
    ph = best.spec.drive_phase

    def build(v):
        return ModelSpec(a0=a0)

    true = np.array([1.0, best.coef[1], best.coef[2], -p["vdw"], p["stiffness"]])
    start = Solution(spec=ModelSpec(a0=a0), coef=true, residual=best.residual,
                     chi2=best.chi2, values=(), phases=(ph,))
    at_truth, ok = oe.refine(start, build, [], max_nfev=60)
    assert ok
    assert abs(at_truth.chi2 - (rows - 6)) < 4 * np.sqrt(2 * rows)
    # the projected phase is the phase the equation error found
    assert abs(at_truth.phases[0] - ph) < 0.05
    fitted, ok = oe.refine(dataclasses.replace(best, spec=ModelSpec(a0=a0), values=(),
                                               phases=(ph,)), build, [], max_nfev=60)
    assert ok and fitted.chi2 <= at_truth.chi2 + 2 * np.sqrt(2 * rows)
