"""ForceIdentifier end to end on small simulated traces: recovery, projection, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.identify.constraints import CalibrationConstraints
from afmlearn.identify.identifier import ForceIdentifier, force_vs_gap
from afmlearn.identify.library import (
    AFMLibrary,
    ContactIndicator,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
)
from afmlearn.identify.projection import HarmonicBalance
from afmlearn.identify.single_problem import build_orbit_problem
from afmlearn.io import read_trace
from afmlearn.preprocess import calibrate

SMALL = AFMLibrary([InversePower(2.0), InversePower(8.0), ContactIndicator(), Indentation(1.5),
                    Indentation(2.5), IndentationRate(0.5), ExponentialDamping(0.1)])
FAST = dict(library=SMALL, n_folds=6, n_a0=6, n_bootstrap=8, max_terms=3)


@pytest.fixture(scope="module")
def lj_trace(tmp_path_factory):
    """Lennard-Jones lever in the attractive regime, 0.1 % noise, 100 periods x 200 samples."""
    from afmlearn.simulate import simulate
    from tests.afmlearn.conftest import _compose  # noqa: PLC0415 - shared composer

    out = tmp_path_factory.mktemp("lj") / "lj.h5"
    simulate(_compose([f"output={out}", "force=lj", "cantilever=soft_lj",
                       "excitation.free_amplitude_ratio=0.1", "noise.level=0.001",
                       "scenario.samples_per_period=200", "scenario.n_periods=100"]))
    return read_trace(out, labels=True)


def test_recovers_the_lennard_jones_attraction_from_noisy_data(lj_trace):
    """Only the z^-2 attraction acts on this orbit; it is found, alone, within 1 %."""
    ide = ForceIdentifier(**FAST).fit(lj_trace)
    m = ide.model_
    assert m.library.names == ["z^-2"]
    true = -lj_trace.labels.model["force"]["parameters"]["attraction"]
    assert m.coefficients[0] == pytest.approx(true, rel=0.01)
    # calibration held: K = 1, D = 1/Q, drive = F_c (within the default boxes)
    assert m.stiffness == pytest.approx(1.0, abs=0.01)
    assert m.damping * lj_trace.quality_factor == pytest.approx(1.0, abs=0.15)
    k, ell = lj_trace.spring_constant_n_per_m, lj_trace.gap_m
    f_true = lj_trace.labels.force_n / (k * ell)
    err = np.sqrt(np.mean((ide.force_ - f_true) ** 2)) / np.ptp(f_true)
    assert err < 0.01
    # the 95 % band brackets the estimate and has finite width
    assert np.all(ide.force_lo_ <= ide.force_ + 1e-12)
    assert np.all(ide.force_hi_ >= ide.force_ - 1e-12)
    assert 0.9 < ide.summary_["state_accuracy_heldout"] <= 1.0
    assert ide.summary_["dissipated_energy_per_cycle"] == pytest.approx(0.0, abs=1e-6)


def test_harmonic_balance_rows_vanish_for_the_true_model(tmp_path, run_sim):
    """Noiseless DMT tapping: the true equation satisfies the projected rows to round-off."""
    metrics, _ = run_sim("force=dmt", "noise.level=0", "scenario.n_periods=40",
                         "scenario.samples_per_period=200", "scenario.settle_periods=3500")
    t = read_trace(metrics["output"], labels=True)
    problem = build_orbit_problem(
        calibrate(t), constraints=CalibrationConstraints(), projection=None,
        heldout_fraction=0.3, n_folds=6, max_harmonics=100, min_harmonics=30, thresholds=None,
        nus=None, n_a0=6, a0_range_m=None, physical_signs=True)
    assert problem.periodic and isinstance(problem.projection, HarmonicBalance)
    par = t.labels.model["force"]["parameters"]
    lib = AFMLibrary([InversePower(2.0), Indentation(1.5)])
    des = problem.design(lib, par["a0"])
    q = t.quality_factor
    # drive fitted freely, everything else true
    lin = des.theta[:, :4]
    force = des.theta[:, 4:] @ np.array([-par["vdw"], par["stiffness"]])
    r = des.y - lin[:, :2] @ np.array([-1 / q, -1.0]) - force
    c, *_ = np.linalg.lstsq(lin[:, 2:], r, rcond=None)
    resid = r - lin[:, 2:] @ c
    assert np.sqrt(np.mean(resid ** 2)) < 2e-4 * np.sqrt(np.mean(des.y ** 2))


def test_term_signs_follow_the_physics():
    """Elastic contact repels, adhesion and van der Waals attract, damping dissipates."""
    assert Indentation(1.5).sign == 1
    assert IndentationRate(0.5).sign == 1
    assert ContactIndicator().sign == -1
    assert InversePower(2.0).sign == -1
    assert InversePower(8.0).sign == 1
    assert ExponentialDamping(0.1).sign == -1


@pytest.fixture(scope="module")
def dmt_fit(tmp_path_factory):
    """DMT tapping, 1 % noise, 60 periods x 300 samples, identified with the small library."""
    from afmlearn.simulate import simulate
    from tests.afmlearn.conftest import _compose  # noqa: PLC0415 - shared composer

    out = tmp_path_factory.mktemp("dmt") / "dmt.h5"
    simulate(_compose([f"output={out}", "force=dmt", "noise.level=0.01",
                       "scenario.samples_per_period=300", "scenario.n_periods=60"]))
    tr = read_trace(out, labels=True)
    return tr, ForceIdentifier(**FAST).fit(tr)


def test_physical_signs_bound_every_candidate(dmt_fit):
    """No candidate support, nor the bagged bands, has a coefficient of the unphysical sign."""
    _, ide = dmt_fit
    lib = ide.model_.library
    for c in ide.candidates_:
        coef = np.asarray(c.coef[0])[-len(SMALL.terms):]
        sg = np.array([t.sign for t in SMALL.terms])
        assert np.all(coef * sg >= -1e-12), (c.n_terms, coef)
    sg = np.array([t.sign for t in lib.terms])
    assert np.all(ide.model_.coefficients * sg >= -1e-12)
    if ide.model_.coefficient_bands is not None:
        assert np.all(ide.model_.coefficient_bands * sg >= -1e-12)


def _true_drive_phase(tr) -> float:
    """Drive phase of the noise-free equation, from the labels' fundamental balance.

    ``x'' + D x' + x = -F + B cos(Omega tau - phi)`` projected on ``e^{-i Omega tau}``:
    ``(1 - Omega^2 + i Omega D) X_1 + F_1 = B e^{-i phi}``.
    """
    k, ell = tr.spring_constant_n_per_m, tr.gap_m
    f = tr.labels.force_n / (k * ell)
    x = np.asarray(tr.labels.modal_m).reshape(-1, f.size).sum(0) / ell
    w0 = 2 * np.pi * tr.resonance_frequency_hz
    om = tr.drive_frequency_hz * 2 * np.pi / w0
    tau = w0 * np.asarray(tr.time_s)
    n = int(np.floor(tau[-1] * om / (2 * np.pi)) * 2 * np.pi / om / (tau[1] - tau[0]))
    e = np.exp(-1j * om * tau[:n])
    x1, f1 = 2 * np.mean(x[:n] * e), 2 * np.mean(f[:n] * e)
    rhs = (1 - om**2 + 1j * om / tr.quality_factor) * x1 + f1
    return float(-np.angle(rhs))


def test_drive_phase_is_the_data_s_and_not_the_mirror_root(dmt_fit):
    """The chosen drive phase matches the noise-free balance; the mirror root loses.

    On a tapping orbit the two conservative roots of the fundamental's balance (force
    gradient of either sign) lie far apart (here ~1.6 rad); picking the wrong one flips the
    sign of the fitted force's fundamental.
    """
    tr, ide = dmt_fit
    phi_true = _true_drive_phase(tr)
    assert len(ide.drive_phase_candidates_) >= 2
    d = [abs(math.remainder(p - phi_true, 2 * math.pi)) for p, _ in ide.drive_phase_candidates_]
    assert max(d) > 0.5  # a far (mirror) candidate was considered ...
    assert abs(math.remainder(ide.model_.drive_phase - phi_true, 2 * math.pi)) < 0.1  # ... and lost


def test_force_vs_gap_splits_approach_and_retraction():
    tau = np.linspace(0, 4 * np.pi, 4001)
    z = 1 - np.cos(tau)
    zd = np.sin(tau)
    f = -0.1 * zd  # dissipative: opposite signs on approach and retraction
    out = force_vs_gap(z, zd, f, n_bins=20)
    assert np.nanmean(out["approach"]) > 0 > np.nanmean(out["retract"])


@pytest.mark.parametrize("kw", [dict(n_folds=1), dict(heldout_fraction=0.9), dict(n_a0=2),
                                dict(n_bootstrap=-1), dict(substeps=0),
                                dict(library="dmt"), dict(projection="weak"),
                                dict(output_error="on"),
                                dict(a0_range_m=(3e-9, 1e-9)), dict(a0_range_m=(0.0, 1e-9)),
                                dict(a0_range_m=(1e-10, float("inf")))])
def test_bad_settings_raise(kw, lj_trace):
    with pytest.raises(ValueError):
        ForceIdentifier(**kw).fit(lj_trace)


def test_bad_data_raise(lj_trace):
    with pytest.raises(ValueError, match="Trace or Calibrated"):
        ForceIdentifier().fit(np.zeros(100))
    with pytest.raises(ValueError, match="true_force"):
        ForceIdentifier(**FAST).fit(lj_trace, true_force=np.zeros(3))


def test_exponent_interval_covers_the_true_exponent(dmt_fit):
    """The 95 % profile interval of the contact exponent contains the simulated 1.5.

    At 1 % noise the exponent trades against ``a0`` and the stiffness, so the interval is
    wide; what must hold is that it is honest (covers the truth) and contains the estimate.
    """
    tr, ide = dmt_fit
    p_true = tr.labels.model["force"]["parameters"]["exponent"]
    lo, hi = ide.summary_["interaction_exponent_interval"]
    assert lo <= p_true <= hi
    assert lo <= ide.summary_["interaction_exponent"] <= hi
    prof = ide.exponent_profile_
    assert prof.shape[1] == 2 and np.all(np.isfinite(prof[:, 1]))
    assert np.all(prof[:, 1] >= prof[:, 1].min())


def test_profile_interval_of_a_parabola():
    """RSS = n0 (1 + (p - 2)^2 / n0 s^2): the 95 % interval is 2 +- 1.96 s (Wilks)."""
    from afmlearn.identify.selection import profile_interval as _profile_interval

    n, s = 10_000, 0.2
    p = np.linspace(0.5, 3.5, 3001)
    rss = 1.0 + (p - 2.0) ** 2 / (n * s**2)  # n log(RSS/RSS_min) ~ ((p - 2) / s)^2
    lo, hi = _profile_interval(np.column_stack([p, rss]), n)
    assert lo == pytest.approx(2 - 1.96 * s, abs=2e-3)
    assert hi == pytest.approx(2 + 1.96 * s, abs=2e-3)


def test_fit_leaves_settings_and_fitted_attributes_only(dmt_fit):
    """No hidden state: after fit the estimator holds its settings and attributes ending in
    ``_`` (scikit-learn contract), nothing private."""
    import inspect

    _, ide = dmt_fit
    settings = set(inspect.signature(ForceIdentifier.__init__).parameters) - {"self"}
    extra = [k for k in vars(ide) if k not in settings
             and not (k.endswith("_") and not k.startswith("_"))]
    assert extra == []
    assert ide.orbit_.problem.heldout_start == ide.heldout_start_
    assert ide.calibrated_ is ide.orbit_.problem.calibrated and ide.joint_ is None


def test_heldout_state_error_separates_the_fit_from_a_detuned_lever(dmt_fit):
    """The held-out score of the identified model is the summary's; a lever 5 % stiffer
    (resonance shifted by 2.5 %, about 10 line widths at Q ~ 440) drifts off the measured
    orbit (measured: 0.065 -> 0.33)."""
    import dataclasses

    from afmlearn.identify.single import HeldoutStateError

    _, ide = dmt_fit
    score = HeldoutStateError()
    pb = ide.orbit_.problem
    e = score.run(pb, ide.model_)
    assert e == pytest.approx(1.0 - ide.summary_["state_accuracy_heldout"], abs=1e-12)
    detuned = dataclasses.replace(ide.model_, stiffness=1.05 * ide.model_.stiffness)
    assert score.run(pb, detuned) > 3 * e
