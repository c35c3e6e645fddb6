"""The hidden-effect generator: reproducible, labelled, tapping, and silent about the cause."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from afmlearn.diagnose.synthetic import (
    CAUSES,
    EFFECT_PAIRS,
    SeriesCase,
    draw_case,
    draw_series_case,
    effect_visibility,
    hidden_series,
    simulate_series,
)
from afmlearn.io import Experiment, read_trace
from afmlearn.preprocess import fit_harmonics


def test_draw_is_seeded_and_covers_the_vocabulary():
    a = [draw_case(np.random.default_rng([1, i])) for i in range(60)]
    b = [draw_case(np.random.default_rng([1, i])) for i in range(60)]
    assert a == b
    assert {c.cause for c in a} == set(CAUSES)
    for c in a:
        assert 150 <= c.quality_factor <= 450 and 1.2 <= c.free_amplitude_ratio <= 1.8
    with pytest.raises(ValueError, match="cause"):
        draw_case(np.random.default_rng(0), cause="gremlins")


def test_trace_carries_truth_only_in_labels(make_trace):
    path, case = make_trace("electrostatic", 5, spp=100, periods=30)
    tr = read_trace(path)
    assert tr.labels is None
    assert "electro" not in path.name and "electro" not in (tr.description or "")
    assert not hasattr(tr, "higher_mode_frequencies_hz") or tr.higher_mode_frequencies_hz is None
    lab = read_trace(path, labels=True).labels
    assert lab.effect == "electrostatic" == case.cause
    assert lab.scalars["regime"] == "repulsive"      # tapping orbits only


# ---------------------------------------------------------------------- set-point series
def test_series_draw_is_seeded_covers_causes_and_pairs():
    a = [draw_series_case(np.random.default_rng([2, i])) for i in range(80)]
    assert a == [draw_series_case(np.random.default_rng([2, i])) for i in range(80)]
    labels = {c.cause for c in a}
    assert set(CAUSES) <= labels                      # every single cause and none
    assert any(len(c.causes) == 2 for c in a)         # and draws with two effects
    for c in a:
        assert 150 <= c.quality_factor <= 450 and 12e-9 <= c.free_amplitude_m <= 40e-9
        sp = np.asarray(c.setpoints)
        assert sp.size == 8 and np.all(np.diff(sp) < 0)          # an approach
        assert 0.25 < sp.min() < 0.5 and 0.75 < sp.max() < 0.95
        assert np.ptp(c.settle_offsets) > 0.1                    # a drive phase per row
        assert set(c.effects) == set(c.causes)
        if len(c.causes) == 2:
            assert c.causes in EFFECT_PAIRS
    assert draw_series_case(np.random.default_rng(1), causes="electrostatic+viscoelastic"
                            ).causes == ("viscoelastic", "electrostatic")
    for bad in ("gremlins", "viscoelastic+viscoelastic",
                "adhesion_hysteresis+contact_geometry", "a+b+c"):
        with pytest.raises(ValueError, match="causes"):
            draw_series_case(np.random.default_rng(0), causes=bad)
    with pytest.raises(ValueError, match="n_points"):
        draw_series_case(np.random.default_rng(0), n_points=0)


@pytest.fixture(scope="module")
def null_series(tmp_path_factory):
    path = tmp_path_factory.mktemp("series") / "recording.h5"
    case = hidden_series(np.random.default_rng([31, 4]), path, causes="none", n_points=4,
                         samples_per_period=100, n_periods=10, noise_level=0.01,
                         free_periods=5)
    return path, case


def test_series_file_carries_truth_only_in_labels(null_series):
    path, case = null_series
    tr = read_trace(path)
    assert tr.labels is None and tr.is_series
    assert tr.deflection_m.shape == (4, 1000)
    np.testing.assert_allclose(tr.gap_m, np.asarray(case.setpoints) * case.free_amplitude_m)
    assert tr.higher_mode_frequencies_hz is None
    assert "none" not in (tr.description or "") and "none" not in path.name
    exp = Experiment.read(path)
    assert exp.kind == "series" and len(exp) == 4
    assert np.all(np.isfinite(exp.drive_phases_rad))
    lab = read_trace(path, labels=True).labels
    assert lab.effect == "none" == case.cause
    assert lab.force_n.shape == (4, 1000) and lab.modal_m.shape == (1, 4, 1000)
    assert lab.scalars["regime"] == "repulsive" or "repulsive" in lab.scalars["regime"]


def test_series_drive_phase_closes_the_energy_balance(null_series):
    """Drive input minus lever damping per cycle, computed with the RECORDED drive phase on
    the noise-free deflection, equals the energy the tip-sample force took (labels): the
    phase is the drive's at each row's first sample (a phase off by 0.3 rad changes the
    balance by 1 - cos(0.3) = 4.5 % of the drive work near resonance and fails)."""
    path, case = null_series
    tr = read_trace(path, labels=True)
    lab = tr.labels
    L = 10e-9                     # only ratios below; any length unit works
    q = case.quality_factor
    b = case.free_amplitude_m / L / q               # drive at resonance: A_free = B Q
    omega = tr.drive_frequency_hz / tr.resonance_frequency_hz                 # = 1
    tau = np.arange(tr.deflection_m.shape[1]) / tr.sample_rate_hz * 2 * np.pi \
        * tr.resonance_frequency_hz
    period = 2 * np.pi / omega
    e_j = np.asarray(lab.scalars["dissipated_energy_j"])

    def balance(v: np.ndarray, phase: float) -> float:
        drive = b * np.cos(omega * tau + phase)
        return float(np.mean(drive * v - v**2 / q) * period)       # [k L^2]

    for i in range(tr.deflection_m.shape[0]):
        x = lab.modal_m[:, i].sum(axis=0) / L
        v = fit_harmonics(tau, x, omega, n_harmonics=40).evaluate(tau, 1)
        e_true = e_j[i] / (tr.spring_constant_n_per_m * L**2)
        phi = float(tr.drive_phase_rad[i])
        scale = float(np.mean(b * np.abs(v)) * period)              # drive work scale
        assert abs(balance(v, phi) - e_true) < 0.005 * scale, (balance(v, phi), e_true, scale)
        assert abs(balance(v, phi + 0.3) - e_true) > 0.02 * scale


def test_series_without_recorded_phase(tmp_path):
    case = draw_series_case(np.random.default_rng(5), causes="higher_mode+detector_nonlinearity",
                            n_points=2)
    path = simulate_series(case, tmp_path / "a.h5", samples_per_period=60, n_periods=6,
                           free_periods=4, drive_phase=False, labels=False)
    tr = read_trace(path)
    assert tr.drive_phase_rad is None and tr.higher_mode_frequencies_hz is None
    assert np.all(np.isnan(Experiment.read(path).drive_phases_rad))
    with pytest.raises(ValueError, match="n_periods"):
        simulate_series(case, tmp_path / "b.h5", n_periods=1)


# ---------------------------------------------------------------------- visibility oracle
def test_harmonic_noise_units_match_white_noise():
    """The oracle's unit: a noisy record minus its noise-free twin gives chi2 ~ 2K + 1 per row
    (K complex harmonics with 2 degrees of freedom, the mean with 1)."""
    from afmlearn.diagnose.synthetic import _row_harmonics, _simulate_series

    case = draw_series_case(np.random.default_rng([7, 1]), causes="none", n_points=8)
    opts = {"samples_per_period": 100, "n_periods": 10, "free_periods": 1, "min_tapping": 0}
    clean = _simulate_series(case, noise_level=0.0, **opts).deflection_m
    noisy = _simulate_series(case, noise_level=0.01, **opts).deflection_m
    k, n, sigma = 20, 1000, 0.01 * case.free_amplitude_m
    w = np.full(k + 1, n / (2 * sigma**2))
    w[0] = n / sigma**2
    chi2 = (np.abs(_row_harmonics(clean, 100, k) - _row_harmonics(noisy, 100, k)) ** 2
            * w).sum(axis=1)
    # mean of 8 rows: expectation 41, std sqrt(2 * 41 / 8) = 3.2
    assert abs(chi2.mean() - (2 * k + 1)) < 4 * 3.2, chi2


def test_visibility_vanishes_with_the_effect_and_grows_with_it():
    case = draw_series_case(np.random.default_rng([7, 2]), causes="electrostatic",
                            n_points=3)
    assert SeriesCase.from_dict(case.to_dict()) == case
    opts = {"samples_per_period": 100, "n_periods": 10, "noise_level": 0.01,
            "n_harmonics": 20}
    def at(volt: float) -> float:
        c = SeriesCase(**{**case.__dict__, "effects": {"electrostatic": {"voltage_v": volt}}})
        v = effect_visibility(c, **opts)["electrostatic"]
        assert len(v["chi2_rows"]) == 3
        return v["chi2_total"]
    assert at(0.0) == 0.0
    weak, strong = at(1.0), at(3.0)
    assert 0.0 < weak < strong
    assert effect_visibility(dataclasses.replace(case, causes=(), effects={}), **opts) == {}
    with pytest.raises(ValueError, match="n_harmonics"):
        effect_visibility(case, samples_per_period=100, n_harmonics=50)


def test_diverged_rows_are_not_recordings(tmp_path, monkeypatch):
    """A row far beyond the free amplitude (an integration failure that came out finite) is
    refused and the draw redrawn; here every orbit counts as diverged (reach limit 0.1)."""
    from afmlearn.diagnose import synthetic

    case = draw_series_case(np.random.default_rng([7, 4]), causes="none", n_points=2)
    opts = {"samples_per_period": 60, "n_periods": 6, "free_periods": 2}
    simulate_series(case, tmp_path / "ok.h5", **opts)           # fine at the real limit
    monkeypatch.setattr(synthetic, "_MAX_REACH", 0.1)
    with pytest.raises(FloatingPointError, match="diverged"):
        simulate_series(case, tmp_path / "bad.h5", **opts)
    assert not (tmp_path / "bad.h5").exists()
    with pytest.raises(RuntimeError, match="no tapping series"):
        hidden_series(np.random.default_rng(0), tmp_path / "c.h5", causes="none", n_points=2,
                      max_draws=2, **opts)


def test_a_row_that_passed_the_contact_onset_in_a_trial_stage_stays_bounded():
    """Regression (a null DMT row at 200 samples/period, one RK4 step per sample): a trial
    stage landed near z = 0 out of contact, z**-2 threw the tip 17.5 free amplitudes into the
    sample. The same row at 100 samples/period (the same step, two per sample) was fine; now
    both agree."""
    from afmlearn.diagnose.synthetic import _simulate_series

    d = {"cause": "none", "causes": [], "quality_factor": 270.3202241651758,
         "free_amplitude_m": 1.956404350728376e-08, "setpoints": [0.4811723729555547],
         "settle_offsets": [0.4451330047688712], "tip_radius_m": 1.486962136572616e-08,
         "hamaker_j": 1.3847995592748072e-19, "reduced_modulus_pa": 1016297364.7227466,
         "a0_m": 2.479367021601547e-10, "effects": {}, "seed": 1284272152}
    case = SeriesCase.from_dict(d)
    rows = [_simulate_series(case, samples_per_period=spp, n_periods=5, noise_level=0.0,
                             free_periods=1, min_tapping=0).deflection_m[0] for spp in (200, 100)]
    reach = [float(np.max(np.abs(r))) / case.free_amplitude_m for r in rows]
    assert reach[0] < 1.0 and reach[0] == pytest.approx(reach[1], rel=1e-6)
