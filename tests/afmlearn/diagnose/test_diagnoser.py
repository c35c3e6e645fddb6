"""Diagnoser: the report contract, bad input, and a null trace reported as ``none``."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser, NullCalibration
from afmlearn.diagnose.diagnoser import (
    Candidate,
    name_cause,
    not_separated,
    null_kind,
    tie_margin,
)
from afmlearn.diagnose.hypotheses import (
    AdhesionHysteresis,
    ContactGeometry,
    DecayingDamping,
    DetectorMap,
    DetectorNonlinearity,
    LongRangeDamping,
    Viscoelastic,
    ViscoelasticTerm,
)
from afmlearn.diagnose.report import diagnose_trace, report_markdown, report_record
from afmlearn.diagnose.synthetic import EFFECT_CAUSES, SeriesCase, simulate_series
from afmlearn.diagnose.ties import chi2_difference_sd, heldout_sign_test
from afmlearn.io import Trace, read_trace, write_trace
from afmlearn.plots.diagnose import plot_all

DESIGN_KEYS = {"cause", "confidence", "baseline", "extended", "gain", "candidates", "figures"}


def test_null_trace_is_none_and_report_follows_design(make_trace, tmp_path):
    path, _ = make_trace("none", 11)
    rep = diagnose_trace(path, tmp_path / "out", figures=plot_all)
    assert DESIGN_KEYS <= set(rep)
    assert rep["cause"] == "none" and rep["gain"] == 0.0
    assert 0.0 <= rep["confidence"] <= 1.0
    assert {"equation", "heldout_nrmse", "spectral_error"} <= set(rep["baseline"])
    assert {"equation", "heldout_nrmse"} <= set(rep["extended"])
    assert [c["cause"] for c in rep["candidates"]] == list(EFFECT_CAUSES)
    for c in rep["candidates"]:
        assert {"cause", "gain", "score", "evidence"} <= set(c)
    on_disk = json.loads((tmp_path / "out" / "report.json").read_text())
    assert on_disk["cause"] == "none"
    for name in rep["figures"]:
        assert (tmp_path / "out" / name).stat().st_size > 5000
    md = (tmp_path / "out" / "report.md").read_text()
    assert "Cause: none" in md and "![spectrum](spectrum.png)" in md
    # the baseline fits a null trace to its noise: held-out error near the floor
    assert rep["baseline"]["heldout_nrmse"] < 2e-3


def test_labels_are_never_read(make_trace, tmp_path, labels_guarded):
    """The diagnosis must not open /labels: make any such read fail loudly."""
    path, _ = make_trace("none", 11)
    diagnose_trace(path, tmp_path / "g", diagnoser=Diagnoser(hypotheses=[Viscoelastic()]))
    assert labels_guarded == [str(path)]


def test_name_cause_rule():
    # significant needs both the evidence and the gain; the largest penalised evidence wins
    idx, conf = name_cause([50.0, 30.0, 1.0], [0.2, 0.4, 0.9], [10.0, 10.0, 10.0], 0.05)
    assert idx == 0 and 0 < conf < 1
    idx, _ = name_cause([50.0, 45.0], [0.2, 0.4], [30.0, 10.0], 0.05)
    assert idx == 1                     # the threshold penalises the flexible extension
    idx, conf = name_cause([5.0, 30.0], [0.5, 0.01], [10.0, 10.0], 0.05)
    assert idx is None and conf > 0.5


def test_name_cause_tie_goes_to_the_heldout_setpoints():
    # set-point series: equal fits (within the tie margin) are decided by the held-out
    # NRMSE of the set-points never fitted; outside the margin the evidence decides
    d, g, t = [25.4, 26.2, 22.1], [0.80, 0.85, 0.84], [7.24, 9.88, 9.88]
    assert name_cause(d, g, t, 0.05)[0] == 0
    assert name_cause(d, g, t, 0.05, heldout=[0.0016, 0.0010, 0.0012])[0] == 1
    assert name_cause(d, g, t, 0.05, heldout=[0.0016, np.nan, np.nan])[0] == 0
    far = [25.4 + tie_margin(25.4) + 3.0, 26.2, 22.1]
    assert name_cause(far, g, t, 0.05, heldout=[0.0016, 0.0010, 0.0012])[0] == 0
    # a tied candidate without held-out gain is no alternative
    assert name_cause(d, [0.8, 0.01, 0.84], t, 0.05, heldout=[0.0016, 0.0010, 0.0012])[0] == 2


def test_chi2_difference_sd_is_the_spread_under_a_new_noise_draw():
    """Two least-squares models of the same data (whitened, unit noise), refitted on every
    new noise draw: the spread of their chi2 difference is 2 ||r_a - r_b|| read off ONE
    draw (exact for fixed predictions; refits absorb at most tr((P_a - P_b)^2) of the
    variance, a few units here against ~10^3)."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1.0, 400)
    mu = 40.0 * np.exp(-3.0 * x) * np.sin(9.0 * x)            # the truth, in noise units
    xa = np.column_stack([np.ones_like(x), x, x**2])            # two wrong models
    xb = np.column_stack([np.ones_like(x), np.exp(-3 * x), np.sin(9 * x)])

    def residual(m, y):
        return m @ np.linalg.lstsq(m, y, rcond=None)[0] - y

    diffs, pred = [], []
    for _ in range(2000):
        y = mu + rng.standard_normal(x.size)
        ra, rb = residual(xa, y), residual(xb, y)
        diffs.append(ra @ ra - rb @ rb)
        pred.append(chi2_difference_sd(ra, rb))
    sd = float(np.std(diffs))
    assert 0.9 * np.median(pred) < sd < 1.05 * np.median(pred), (sd, np.median(pred))
    assert sd > 50.0                       # a real spread, not a degenerate case
    # the noise common to both fits cancels: the same model twice has no spread
    assert chi2_difference_sd(ra, ra) == 0.0
    assert np.isnan(chi2_difference_sd(ra, ra[:-1]))


def test_heldout_sign_test_counts_setpoints():
    a = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    assert heldout_sign_test(a, [2.0] * 8) == (8, 8, pytest.approx(2 / 2**8))
    k, n, p = heldout_sign_test(a, [2.0] * 7 + [0.5])
    assert (k, n) == (7, 8) and p == pytest.approx(18 / 256)       # not below 0.05
    k, n, p = heldout_sign_test(a[:4], [2.0] * 4)
    assert (k, n) == (4, 4) and p == pytest.approx(0.125)        # 4 never separate
    k, n, p = heldout_sign_test([1.0, np.nan, 1.0], [2.0, 2.0, 1.0])
    assert (k, n) == (1, 1)                 # NaN and equal set-points do not count
    assert heldout_sign_test([np.nan], [1.0]) == (0, 0, 1.0)
    with pytest.raises(ValueError, match="named and other"):
        heldout_sign_test([1.0, 2.0], [1.0])


def test_chi2_noise_widens_the_reported_tie():
    """Outside the fixed margin but within two standard deviations of the chi2 difference's
    noise: the naming still reads the evidence (the fixed margin), the report says the tie."""
    assert tie_margin(300.0) == 45.0 and tie_margin(300.0, 30.0) == 60.0
    assert tie_margin(300.0, 10.0) == 45.0 and tie_margin(300.0, float("nan")) == 45.0
    assert name_cause([300.0, 250.0], [0.8, 0.8], [10.0, 10.0], 0.05,
                      heldout=[0.002, 0.001])[0] == 0
    r, r2 = np.zeros(20), np.zeros(20)
    r2[0] = 15.0                                                  # sd 30
    per = [0.002, 0.001, 0.002, 0.001]
    cands = [_cand("viscoelastic", 300.0, r, per), _cand("long_range_damping", 250.0, r2,
                                                          per[::-1], threshold=10.0)]
    cands[0].threshold = 10.0
    assert [t.cause for t in not_separated(cands, 0, 0.05)] == ["long_range_damping"]
    r2[0] = 5.0                                                   # sd 10: separated
    assert not_separated(cands, 0, 0.05) == []


def _cand(cause, drop, residual, per_obs, *, gain=0.5, threshold=9.88):
    per = np.asarray(per_obs, float)
    return Candidate(cause=cause, model=None, chi2=600.0 - drop, delta_chi2=drop,
                     threshold=threshold, heldout_nrmse=float(np.nanmedian(per)), gain=gain,
                     significant=True, evidence="", n_parameters=2,
                     solution=dataclasses.make_dataclass("S", ["residual"])(
                         np.asarray(residual, float)),
                     nrmse_per_observation=per)


def test_the_decision_reads_the_causes_own_gain_and_reports_the_nrmse_one():
    """A second mode refuted by the NRMSE of unseen set-points (-0.12) but seen on its own
    harmonics (+0.83): the decision reads the latter, the report keeps the former."""
    c = _cand("higher_mode", 521.0, np.zeros(3), [0.001] * 4, gain=-0.12, threshold=12.07)
    assert c.deciding_gain == -0.12
    c.decision_gain = 0.834
    assert c.deciding_gain == 0.834 and c.gain == -0.12
    other = _cand("viscoelastic", 519.0, np.zeros(3), [0.002] * 4, gain=0.5, threshold=7.24)
    assert [t.cause for t in not_separated([other, c], 0, 0.05)] == ["higher_mode"]
    c.decision_gain = 0.01
    assert not_separated([other, c], 0, 0.05) == []


def test_ties_are_reported_not_hidden():
    """The session-7 neck draw's pattern: neck / damping / visco drops 217 / 222 / 218, the
    fits close (chi2 noise sd ~12), the held-out set-points split: not separated, said in
    one line. A candidate separated by the held-out set-points (better at 8 of 8), or far
    in chi2, or without held-out gain, is no tie."""
    r = np.zeros(50)
    r2 = r.copy()
    r2[0] = 6.0                                         # sd 12
    mixed = [0.001, 0.002, 0.001, 0.002, 0.001, 0.002, 0.001, 0.002]
    other = [0.0015] * 8
    cands = [_cand("adhesion_hysteresis", 217.0, r, mixed),
             _cand("long_range_damping", 222.0, r2, other),
             _cand("viscoelastic", 218.0, r2, [0.003] * 8, threshold=7.24),
             _cand("detector_nonlinearity", 90.0, r2, other),
             _cand("contact_geometry", 216.0, r2, other, gain=0.01)]
    ties = not_separated(cands, 0, 0.05)
    assert [t.cause for t in ties] == ["long_range_damping"]
    t = ties[0]
    assert (t.better_at, t.n) == (4, 8) and t.chi2_sd == pytest.approx(12.0)
    assert t.text("adhesion_hysteresis").startswith(
        "adhesion_hysteresis; not separated from long_range_damping on these data (drops 217 "
        "vs 222")
    # the named cause may have the smaller drop (picked by the held-out median): still a tie
    assert [t.cause for t in not_separated(cands, 1, 0.05)] == ["adhesion_hysteresis"]


@pytest.mark.parametrize("kwargs, match", [
    ({"heldout_fraction": 0.9}, "heldout_fraction"),
    ({"grid": 1000}, "grid"),
    ({"min_harmonics": 1}, "min_harmonics"),
    ({"max_harmonics": 5}, "max_harmonics"),
    ({"hypotheses": ["viscoelastic"]}, "hypotheses"),
    ({"calibration": {"viscoelastic": 3.0}}, "calibration"),
])
def test_bad_settings_name_the_parameter(make_trace, kwargs, match):
    path, _ = make_trace("none", 11)
    with pytest.raises(ValueError, match=match):
        Diagnoser(**kwargs).fit(read_trace(path))


def test_bad_input(make_trace, tmp_path):
    path, _ = make_trace("none", 11)
    tr = read_trace(path)
    short = Trace(tr.deflection_m[: int(8 * 200)], sample_rate_hz=tr.sample_rate_hz,
                  drive_frequency_hz=tr.drive_frequency_hz, gap_m=tr.gap_m,
                  spring_constant_n_per_m=tr.spring_constant_n_per_m,
                  quality_factor=tr.quality_factor,
                  resonance_frequency_hz=tr.resonance_frequency_hz,
                  free_amplitude_m=tr.free_amplitude_m)
    with pytest.raises(ValueError, match="periods"):
        Diagnoser().fit(short)
    bad = tmp_path / "nan.h5"
    y = tr.deflection_m.copy()
    y[100] = np.nan
    with pytest.raises(ValueError):
        write_trace(Trace(y, sample_rate_hz=tr.sample_rate_hz,
                          drive_frequency_hz=tr.drive_frequency_hz, gap_m=tr.gap_m,
                          spring_constant_n_per_m=tr.spring_constant_n_per_m,
                          quality_factor=tr.quality_factor,
                          resonance_frequency_hz=tr.resonance_frequency_hz), bad)
        Diagnoser().fit(read_trace(bad))


def test_calibration_shipped_covers_every_cause():
    cal = NullCalibration.default()
    assert set(cal.thresholds) == set(EFFECT_CAUSES)
    assert all(v > 0 for v in cal.thresholds.values()) and 0 < cal.min_gain < 1
    with pytest.raises(ValueError, match="cause"):
        cal.threshold("gremlins")


def test_sweep_needs_a_row(make_trace, tmp_path):
    path, _ = make_trace("none", 11)
    tr = read_trace(path)
    n = tr.deflection_m.size
    sweep = tmp_path / "sweep.h5"
    with h5py.File(path) as f:
        attrs = dict(f.attrs)
    write_trace(Trace(np.vstack([tr.deflection_m, tr.deflection_m]),
                      sample_rate_hz=tr.sample_rate_hz,
                      drive_frequency_hz=np.array([tr.drive_frequency_hz] * 2),
                      gap_m=tr.gap_m, spring_constant_n_per_m=tr.spring_constant_n_per_m,
                      quality_factor=tr.quality_factor,
                      resonance_frequency_hz=tr.resonance_frequency_hz), sweep)
    assert n > 0 and attrs
    with pytest.raises(ValueError, match="row"):
        diagnose_trace(sweep, tmp_path / "s")
    with pytest.raises(ValueError, match="row"):
        diagnose_trace(sweep, tmp_path / "s", row=5)


# ---------------------------------------------------------------------- experiments (issue 12)
def test_series_report_has_causes_and_per_setpoint_figures(make_series, tmp_path):
    """A visco-elastic series: named from whole set-points held out (leave one out)."""
    path, case = make_series("viscoelastic", 5)
    dg = Diagnoser(hypotheses=[Viscoelastic(), ContactGeometry()], max_folds=4)
    rep = diagnose_trace(path, tmp_path / "out", diagnoser=dg)
    assert DESIGN_KEYS | {"causes", "observations", "heldout"} <= set(rep)
    assert rep["heldout"]["design"] == "leave-one-out"
    assert rep["cause"] == "viscoelastic" == rep["causes"][0]["cause"], rep["candidates"]
    for c in rep["causes"]:
        assert {"cause", "gain", "evidence"} <= set(c)
    assert rep["gain"] > 0.3
    obs = rep["observations"]
    assert len(obs) == 4 and sorted(o["index"] for o in obs) == [0, 1, 2, 3]
    base = np.array([o["baseline_heldout_nrmse"] for o in obs])
    ext = np.array([o["extended_heldout_nrmse"] for o in obs])
    assert np.all(np.isfinite(base)) and np.all(np.isfinite(ext))
    # the gain is the typical (median) per-set-point improvement, on set-points never fitted
    assert rep["gain"] == pytest.approx(1 - np.median(ext) / np.median(base), rel=1e-9)
    assert np.all(ext < base)
    ce = rep["contact_exponent"]
    assert ce is not None and ce["interval_95"][0] <= ce["exponent"] <= ce["interval_95"][1]
    md = (tmp_path / "out" / "report.md").read_text()
    assert "Held-out NRMSE per set-point" in md and "leave-one-out" in md
    # ties: a list (empty when the data separate the named cause from every other)
    assert isinstance(rep["not_separated"], list)
    tie = {"cause": "viscoelastic", "step": 1, "not_separated_from": "contact_geometry",
           "text": "viscoelastic; not separated from contact_geometry on these data (drops "
                   "217 vs 222)"}
    assert "**Tie:** viscoelastic; not separated from contact_geometry" in report_markdown(
        {**rep, "not_separated": [tie]}, {})
    # a gain measured on the cause's own signature decided: the NRMSE gain is still shown
    c0 = {**rep["candidates"][0], "gain": -0.12, "decision_gain": 0.834,
          "decision_gain_basis": "own signature"}
    md = report_markdown({**rep, "candidates": [c0, *rep["candidates"][1:]]}, {})
    assert "-0.120 (decided by +0.834: own signature)" in md


def test_ramp_is_diagnosed_through_quasi_steady_windows(make_series):
    path, _ = make_series("none", 3)
    tr = read_trace(path)
    rows = [tr.row(i) for i in range(tr.n_points)]
    y = np.concatenate([r.deflection_m for r in rows])
    gap = np.concatenate([np.full(r.deflection_m.size, float(r.gap_m)) for r in rows])
    ramp = Trace(y, **{**rows[0].metadata(), "gap_m": gap, "drive_phase_rad": None})
    dg = Diagnoser(hypotheses=[], ramp_window_periods=20.0).fit(ramp)
    assert dg.cause_ == "none" and dg.design_ == "leave-one-out"
    assert {o.kind for o in dg.observations_} == {"ramp_window"}
    # the baseline is the truth: windows never fitted are predicted near the noise floor
    # (measured: 0.0011-0.0014; the largest-gap window 0.010, against 0.0006 for the same
    # record diagnosed as a series with its recorded phases -- not understood yet)
    nrmse = sorted(o.baseline_nrmse for o in dg.observations_)
    assert nrmse[len(nrmse) // 2] < 0.003 and nrmse[-1] < 0.02


def test_series_labels_are_never_read(make_series, tmp_path, labels_guarded):
    path, _ = make_series("none", 3)
    rep = diagnose_trace(path, tmp_path / "g", diagnoser=Diagnoser(hypotheses=[]))
    assert labels_guarded == [str(path)]
    assert rep["cause"] == "none" and len(rep["observations"]) == 4


def test_observations_must_share_the_calibration(make_series):
    path, _ = make_series("none", 3)
    tr = read_trace(path)
    a, b = tr.row(0), tr.row(1)
    other = Trace(b.deflection_m, **{**b.metadata(), "quality_factor": 2 * b.quality_factor})
    with pytest.raises(ValueError, match="quality_factor"):
        Diagnoser(hypotheses=[]).fit([a, other])
    with pytest.raises(ValueError, match="row"):
        diagnose_trace(path, "unused", row=7)


def test_two_effects_are_named_step_by_step(make_series):
    """Visco-elastic loss and a detector nonlinearity at once: both named, the second tested
    against the model extended by the first, each adding held-out gain. The loss channel is
    held to the dissipative family (on 4 x 20 periods this draw names long-range damping for
    the visco-elastic loss: the measured tie of docs/diagnose.md). The detector cannot come
    first: alone it drops chi2 by 34,509 but hides the missing loss in its drive phases
    (0.05-0.09 rad off the recorded ones), which the held-out set-points, predicted with the
    recorded phases, expose (gain -0.59); the loss term comes first with gain ~0.17 since the
    damping term's start is also scanned by output error (docs/diagnose.md, session 4)."""
    path, case = make_series("viscoelastic+detector_nonlinearity", 7)
    dg = Diagnoser(hypotheses=[Viscoelastic(), DetectorNonlinearity(), LongRangeDamping()])
    dg.fit(read_trace(path))
    named = [s.cause for s in dg.causes_]
    assert len(named) == 2 and "detector_nonlinearity" in named, dg.causes_
    assert {"viscoelastic", "long_range_damping"} & set(named), dg.causes_
    assert all(s.gain > 0 for s in dg.causes_)
    # the second cause was tested against the extended model and added to it
    assert dg.gain_ > dg.causes_[0].gain
    assert dg.extended_.spec.get(DetectorMap) is not None
    assert (dg.extended_.spec.get(ViscoelasticTerm), dg.extended_.spec.get(DecayingDamping)) \
        != (None, None)


def test_null_calibration_is_chosen_by_the_design(monkeypatch, tmp_path):
    """Series at several free amplitudes read their own null thresholds, else the one-amplitude
    series' (and the report's source says so), else the single-record ones."""
    import afmlearn.diagnose.diagnoser as dmod

    class _Files:
        def files(self, package):
            return tmp_path

    monkeypatch.setattr(dmod, "resources", _Files())
    single = {"thresholds": {"viscoelastic": 1.0}, "min_gain": 0.05, "source": "one"}
    series = {"thresholds": {"viscoelastic": 2.0}, "min_gain": 0.05, "source": "ser"}
    amps = {"thresholds": {"viscoelastic": 3.0}, "min_gain": 0.05, "source": "amp"}
    path = tmp_path / "null_calibration.json"
    path.write_text(json.dumps({**single, "series": series, "series_amplitudes": amps}))
    assert NullCalibration.default("series_amplitudes").threshold("viscoelastic") == 3.0
    assert NullCalibration.default("series").threshold("viscoelastic") == 2.0
    path.write_text(json.dumps({**single, "series": series}))
    cal = NullCalibration.default("series_amplitudes")
    assert cal.threshold("viscoelastic") == 2.0 and "no several-amplitude" in cal.source
    path.write_text(json.dumps(single))
    cal = NullCalibration.default("series_amplitudes")
    assert cal.threshold("viscoelastic") == 1.0 and "no series calibration" in cal.source
    with pytest.raises(ValueError, match="series_amplitudes"):
        NullCalibration.default("two")
    # no recorded drive phase: its own section, else the recorded-phase series' (said so)
    nophase = {"thresholds": {"viscoelastic": 4.0}, "min_gain": 0.05, "source": "nph"}
    path.write_text(json.dumps({**single, "series": series, "series_nophase": nophase}))
    assert NullCalibration.default("series_nophase").threshold("viscoelastic") == 4.0
    assert NullCalibration.default("series").threshold("viscoelastic") == 2.0
    path.write_text(json.dumps({**single, "series": series}))
    cal = NullCalibration.default("series_nophase")
    assert cal.threshold("viscoelastic") == 2.0 and "without the drive phase" in cal.source


def test_shipped_nophase_thresholds_come_from_their_own_nulls():
    """The shipped ``series_nophase`` section: >= 32 null series with the drive phase removed,
    seeded apart from the evaluation draws (seed 2027), every threshold at least the smallest
    chi-square floor (1 parameter at the Bonferroni level), and read without a fallback."""
    from importlib import resources

    from scipy import stats

    d = json.loads(resources.files("afmlearn.diagnose").joinpath("null_calibration.json")
                   .read_text())
    sec = d["series_nophase"]
    prov = sec["provenance"]
    assert prov["drive_phase"] is False and prov["free_amplitudes"] == 1
    assert prov["n_null_series"] >= 32 and prov["seed"] != 2027
    assert prov["set_id"] not in (d["series"]["provenance"]["set_id"], 3)
    floor = stats.chi2.ppf(1 - prov["family_rate"] / len(sec["thresholds"]), 1)
    assert min(sec["thresholds"].values()) >= floor - 1e-9
    cal = NullCalibration.default("series_nophase")
    assert cal.thresholds == sec["thresholds"] and "drive phase not recorded" in cal.source
    assert "no calibration" not in cal.source


def test_null_thresholds_follow_the_design():
    """One record, one amplitude with / without every recorded phase, several amplitudes."""
    assert null_kind(1, 1, True) == "single" and null_kind(1, 1, False) == "single"
    assert null_kind(8, 1, True) == "series"
    assert null_kind(8, 1, False) == "series_nophase"
    assert null_kind(8, 2, True) == "series_amplitudes"
    assert null_kind(8, 2, False) == "series_amplitudes"


def test_a_series_without_its_phases_reads_the_nophase_thresholds(make_series):
    """Diagnoser.fit picks the thresholds by the design: the same null file with its drive
    phases removed reads the no-phase section (a Diagnoser with no hypothesis: cheap)."""
    path, _ = make_series("none", 3)
    tr = read_trace(path)
    rows = [dataclasses.replace(tr.row(i), drive_phase_rad=None) for i in range(tr.n_points)]
    want = NullCalibration.default("series_nophase")
    assert Diagnoser(hypotheses=[]).fit(rows).calibration_ == want
    assert Diagnoser(hypotheses=[]).fit(tr).calibration_ == NullCalibration.default("series")


def test_outcome_does_not_depend_on_the_order_of_the_causes(make_series):
    """The same draw with the causes tried in two orders: the same causes named and the same
    first-step evidence per cause (each candidate is shot from the current model's own orbits,
    not from the warm starts the candidate before it left)."""
    path, _ = make_series("viscoelastic+detector_nonlinearity", 7)
    tr = read_trace(path)
    kinds = [Viscoelastic, LongRangeDamping, DetectorNonlinearity]
    runs = [Diagnoser(hypotheses=[k() for k in order]).fit(tr)
            for order in (kinds, kinds[::-1])]
    named = [[s.cause for s in dg.causes_] for dg in runs]
    assert named[0] == named[1]
    drops = [{c.cause: c.delta_chi2 for c in dg.candidates_} for dg in runs]
    assert drops[0].keys() == drops[1].keys()
    for cause, d in drops[0].items():
        assert drops[1][cause] == pytest.approx(d, rel=1e-6, abs=1e-6), cause


@pytest.mark.slow
def test_cone_exponent_is_named_from_unseen_setpoints(make_series):
    """A cone-like contact law on 8 set-points (1,000 samples/period, 0.5 % noise, 100
    periods): named contact_geometry, with an exponent interval that contains the truth and
    excludes the sphere's 1.5.

    Whether the interval is also bounded above depends on the machine's floating point
    (measured on this draw, truth 2.37: not bounded when it was written, a strict xfail; session 10,
    AMD EPYC with OpenBLAS Haswell kernels: 2.47 [2.19, 3.14], drop 57.5 against 7.24, gain
    0.84), so it is not asserted; the exponent goal is measured in ``identify_seeds``."""
    path, case = make_series("contact_geometry", 1, n_points=8, spp=1000, periods=100,
                             noise=0.005)
    dg = Diagnoser(hypotheses=[ContactGeometry(), Viscoelastic()]).fit(read_trace(path))
    truth = case.effects["contact_geometry"]["exponent"]
    assert dg.cause_ == "contact_geometry", dg.candidates_
    lo, hi = dg.exponent_interval_
    assert 1.5 < lo <= truth <= hi


@pytest.mark.slow
def test_a_null_series_without_its_phases_names_nothing(make_series):
    """The drive phases removed from a null series: every phase is fitted, and no cause's
    first-step drop reaches its threshold (session 4, before the phases were polished: 5 of 20
    null 8-set-point series named a cause without their phases, 0 of the same 20 with them;
    drops up to 1,400x the threshold, every extension "explaining" the unfinished baseline)."""
    path, _ = make_series("none", 3)
    tr = read_trace(path)
    rows = [dataclasses.replace(tr.row(i), drive_phase_rad=None) for i in range(tr.n_points)]
    dg = Diagnoser().fit(rows)
    assert dg.cause_ == "none"
    for c in dg.candidates_:
        assert c.delta_chi2 < c.threshold, (c.cause, c.delta_chi2, c.threshold)
    # and the no-phase baseline fits about as well as the recorded-phase one (it has every
    # phase free, so at the optimum it is below it): an unconverged phase search shows here
    # first (before the polish: 16,205 against 285 on a bench null). Not below it: its a0
    # valley is flat and the output-error refinement slow along it (measured here: 204.1
    # against 201.7, a0 0.049 vs 0.0034 L_ref; 300 more iterations reach 200.1 at a0 0.019)
    rec = Diagnoser(hypotheses=[]).fit(tr)
    assert dg.baseline_chi2_ <= 1.03 * rec.baseline_chi2_


#: a seed-2026 development draw (benchmarks/bench_diagnose.py set_id 3, adhesion_hysteresis
#: index 0; 8 set-points x 30 periods, 200 samples/period, 1 % noise): the JKR neck whose
#: neck / damping / visco fits tie (chi2 366.2 / 361.6 / 365.1 against the truth law's 373)
NECK_TIE = {
    "causes": ["adhesion_hysteresis"], "quality_factor": 189.66452595467518,
    "free_amplitude_m": 1.9293376565300568e-08,
    "setpoints": [0.9049329056271254, 0.8273189628791634, 0.7352516982990762,
                  0.6592309724116246, 0.5816806009280548, 0.5217505580636531,
                  0.4189736030189014, 0.34179741181841455],
    "settle_offsets": [0.6604356016971168, 0.48324353719640334, 0.42586362753841467,
                       0.8890562134951094, 0.9382807045345221, 0.7526125215203732,
                       0.3324654789702688, 0.738551344873965],
    "tip_radius_m": 1.637089357898396e-08, "hamaker_j": 1.1639712623333508e-19,
    "reduced_modulus_pa": 3067285065.3104353, "a0_m": 3.0594558652132964e-10,
    "effects": {"adhesion_hysteresis": {"work_of_adhesion_j_per_m2": 0.20849022802706235}},
    "seed": 1582017597}


@pytest.mark.slow
def test_a_tie_between_dissipative_causes_is_reported(tmp_path):
    """The neck draw above (~30 s CPU): the three dissipative fits drop chi2 by 217 / 222 /
    218, within each other's noise (sd of the differences 4-8), and the held-out set-points
    split; the diagnosis names one (the held-out median's choice) and says that the data do
    not separate it from the others, the true neck among them."""
    path = simulate_series(SeriesCase.from_dict(NECK_TIE), tmp_path / "neck.h5",
                           samples_per_period=200, n_periods=30.0, noise_level=0.01)
    dg = Diagnoser(hypotheses=[AdhesionHysteresis(), LongRangeDamping(), Viscoelastic()])
    dg.fit(read_trace(path))
    ties = dg.causes_[0].ties
    msg = f"named {[s.cause for s in dg.causes_]}, ties {ties}"
    assert ties, msg
    assert "adhesion_hysteresis" in {dg.cause_, *(t.cause for t in ties)}, msg
    for t in ties:
        assert abs(t.delta_chi2 - t.named_delta_chi2) < tie_margin(t.delta_chi2, t.chi2_sd)
        assert t.p >= 0.05 and t.n == 8
    rec = report_record(dg, input_path=path, row=None, figures=[], runtime_s=0.0)
    assert {r["not_separated_from"] for r in rec["not_separated"]} == {t.cause for t in ties}
    md = report_markdown(rec, {})
    assert f"**Tie:** {dg.cause_}; not separated from {ties[0].cause} on these data" in md
