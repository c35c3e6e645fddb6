"""ForceIdentifier end to end on small simulated traces: recovery, projection, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.identify.identifier import ForceIdentifier, force_vs_gap
from afmlearn.identify.library import (
    AFMLibrary,
    ContactIndicator,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
)
from afmlearn.io import read_trace

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
    ide = ForceIdentifier(**FAST)
    import afmlearn.identify.identifier as mod

    class Stop(Exception):
        pass

    def stop(*a, **k):
        raise Stop

    orig = mod.ForceIdentifier._select
    mod.ForceIdentifier._select = stop
    try:
        with pytest.raises(Stop):
            ide.fit(t)
    finally:
        mod.ForceIdentifier._select = orig
    par = t.labels.model["force"]["parameters"]
    lib = AFMLibrary([InversePower(2.0), Indentation(1.5)])
    des = ide._design(lib, par["a0"])
    q = t.quality_factor
    # drive fitted freely, everything else true
    lin = des.theta[:, :4]
    force = des.theta[:, 4:] @ np.array([-par["vdw"], par["stiffness"]])
    r = des.y - lin[:, :2] @ np.array([-1 / q, -1.0]) - force
    c, *_ = np.linalg.lstsq(lin[:, 2:], r, rcond=None)
    resid = r - lin[:, 2:] @ c
    assert np.sqrt(np.mean(resid ** 2)) < 2e-4 * np.sqrt(np.mean(des.y ** 2))


def test_force_vs_gap_splits_approach_and_retraction():
    tau = np.linspace(0, 4 * np.pi, 4001)
    z = 1 - np.cos(tau)
    zd = np.sin(tau)
    f = -0.1 * zd  # dissipative: opposite signs on approach and retraction
    out = force_vs_gap(z, zd, f, n_bins=20)
    assert np.nanmean(out["approach"]) > 0 > np.nanmean(out["retract"])


@pytest.mark.parametrize("kw", [dict(n_folds=1), dict(heldout_fraction=0.9), dict(n_a0=2),
                                dict(n_bootstrap=-1), dict(substeps=0),
                                dict(library="dmt"), dict(projection="weak")])
def test_bad_settings_raise(kw, lj_trace):
    with pytest.raises(ValueError):
        ForceIdentifier(**kw).fit(lj_trace)


def test_bad_data_raise(lj_trace):
    with pytest.raises(ValueError, match="Trace or Calibrated"):
        ForceIdentifier().fit(np.zeros(100))
    with pytest.raises(ValueError, match="true_force"):
        ForceIdentifier(**FAST).fit(lj_trace, true_force=np.zeros(3))
