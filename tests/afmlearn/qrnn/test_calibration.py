"""Coupling calibration: monotone calibrators with known answers, the flag threshold honours the
stated false-flag rate on its calibration set, and a calibrated checkpoint loads and is used."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from afmlearn.io import Experiment, Trace
from afmlearn.qrnn.calibration import (
    CouplingCalibration,
    IsotonicCalibrator,
    PlattCalibrator,
    expected_calibration_error,
    flag_threshold,
    reliability_curve,
)
from afmlearn.qrnn.evidence import coupling_probability
from afmlearn.qrnn.infer import load_module, predict_trace
from afmlearn.qrnn.train import export_checkpoint


def _logit(p):
    return np.log(p) - np.log1p(-p)


def _draw(n: int, a: float, b: float, seed: int = 0):
    """Raw scores and labels whose true P(coupled | s) = sigmoid(a logit(s) + b)."""
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.001, 0.999, n)
    p_true = 1.0 / (1.0 + np.exp(-(a * _logit(s) + b)))
    return s, rng.uniform(size=n) < p_true, p_true


def test_platt_recovers_a_known_logistic_map():
    s, y, _ = _draw(20000, a=2.0, b=-1.5)
    cal = PlattCalibrator().fit(s, y)
    assert cal.a_ == pytest.approx(2.0, rel=0.06)
    assert cal.b_ == pytest.approx(-1.5, abs=0.12)


@pytest.mark.parametrize("make", [PlattCalibrator, IsotonicCalibrator])
def test_calibrators_are_monotone_and_calibrated(make):
    s, y, p_true = _draw(4000, a=0.7, b=2.0, seed=1)   # raw scores far too low (as OOD)
    cal = make().fit(s, y)
    grid = np.linspace(0.0, 1.0, 501)
    p = cal.predict(grid)
    assert np.all(np.diff(p) >= -1e-12) and p.min() >= 0.0 and p.max() <= 1.0
    s2, y2, _ = _draw(4000, a=0.7, b=2.0, seed=2)      # fresh data from the same law
    assert expected_calibration_error(cal.predict(s2), y2) < 0.04
    assert expected_calibration_error(s2, y2) > 0.2   # the raw score is not a probability


def test_isotonic_pav_known_answer():
    cal = IsotonicCalibrator().fit([0.1, 0.2, 0.3, 0.4], [0, 1, 0, 1])
    np.testing.assert_allclose(cal.predict([0.1, 0.25, 0.4]), [0.0, 0.5, 1.0])


@pytest.mark.parametrize("rate", [0.01, 0.05, 0.2])
def test_threshold_honours_the_stated_rate_on_the_calibration_set(rate):
    rng = np.random.default_rng(3)
    p = np.concatenate([rng.beta(2, 5, 997), rng.beta(5, 2, 103)])
    y = np.r_[np.zeros(997, bool), np.ones(103, bool)]
    t = flag_threshold(p, y, false_flag_rate=rate)
    neg = np.sort(p[~y])
    assert np.mean(neg >= t) <= rate
    # the lowest such threshold: one more negative flagged would break the rate
    k = int(np.floor(rate * neg.size))
    assert np.mean(neg >= neg[-(k + 1)]) > rate
    cc = CouplingCalibration.fit(p, y, false_flag_rate=rate)
    assert cc.source["calibration_false_flag_rate"] <= rate


def test_bad_calibration_input():
    with pytest.raises(ValueError, match="coupled and uncoupled"):
        PlattCalibrator().fit([0.2, 0.3], [0, 0])
    with pytest.raises(ValueError, match="false_flag_rate"):
        flag_threshold([0.2, 0.3], [0, 1], false_flag_rate=0.0)
    with pytest.raises(ValueError, match="in \\[0, 1\\]"):
        PlattCalibrator().fit([0.2, 1.3], [0, 1])


def test_reliability_curve_counts():
    r = reliability_curve([0.05, 0.15, 0.95, 0.96], [0, 0, 1, 0], n_bins=10)
    assert r["count"].sum() == 4 and r["count"][9] == 2
    assert r["observed"][9] == pytest.approx(0.5)


def test_calibrated_checkpoint_loads_and_sets_the_flag(tiny_run, tmp_path):
    module, run, _ = load_module(tiny_run["checkpoint"])
    # train() calibrates on the validation cantilevers and stores it in the export
    shipped = CouplingCalibration.from_dict(run["calibration"])
    assert 0.0 < shipped.threshold <= 1.0 and shipped.false_flag_rate == pytest.approx(0.05)
    assert shipped.source["calibration_false_flag_rate"] <= 0.05
    s, y, _ = _draw(500, a=1.0, b=0.5, seed=4)
    cal = CouplingCalibration.fit(s, y, calibrator=IsotonicCalibrator(), false_flag_rate=0.1)
    path = export_checkpoint(module, tmp_path / "cal.ckpt", calibration=cal)
    raw = torch.load(path, map_location="cpu", weights_only=True)   # plain types only
    assert raw["afmlearn"]["calibration"]["threshold"] == pytest.approx(cal.threshold)
    module2, run2, _ = load_module(path)
    back = CouplingCalibration.from_dict(run2["calibration"])
    np.testing.assert_allclose(back.probability(s), cal.probability(s))
    # a set-point series: one calibrated probability per set-point
    f0, fs, n = 300e3, 64 * 300e3, 64 * 8
    t = np.arange(n) / fs
    rows = np.array([10e-9 * np.cos(2 * np.pi * f0 * t)
                     + a * np.cos(2 * np.pi * 6 * f0 * t) for a in (0.0, 1e-9, 2e-9)])
    series = Trace(rows, sample_rate_hz=fs, spring_constant_n_per_m=40.0, quality_factor=400.0,
                   resonance_frequency_hz=f0, drive_frequency_hz=f0,
                   gap_m=np.array([12e-9, 9e-9, 6e-9]))
    summary = predict_trace(series, module2, run2)["summary"]
    assert summary["calibrated"] and summary["is_series"] and summary["n_traces"] == 3
    assert summary["threshold"] == pytest.approx(cal.threshold)
    for row in summary["traces"]:
        assert row["score"] == pytest.approx(float(cal.probability([row["raw_score"]])[0]))
        assert row["flag"] == (row["score"] >= cal.threshold)
    ev = coupling_probability(Experiment.from_trace(series), checkpoint=path)
    np.testing.assert_allclose(ev.probability, [r["score"] for r in summary["traces"]])
    np.testing.assert_allclose(ev.gap_m, [12e-9, 9e-9, 6e-9])
    assert ev.calibrated and ev.false_flag_rate == pytest.approx(0.1)
    assert ev.max_probability == pytest.approx(ev.probability.max())


def test_per_kind_calibration_sets_the_threshold_of_the_record_kind(tiny_run, tmp_path):
    """A checkpoint with calibrations by kind: set-points use the `steady` one, sweeps `all`'s
    fallback unless a `sweep` one exists."""
    module, _, _ = load_module(tiny_run["checkpoint"])
    s, y, _ = _draw(600, a=1.0, b=0.0, seed=5)
    cal_all = CouplingCalibration.fit(s, y, false_flag_rate=0.05)
    cal_steady = CouplingCalibration.fit(s, y, false_flag_rate=0.2)
    path = export_checkpoint(module, tmp_path / "kinds.ckpt",
                             calibration={"all": cal_all, "steady": cal_steady})
    _, run, _ = load_module(path)
    f0, fs = 300e3, 64 * 300e3
    t = np.arange(64 * 8) / fs
    x = 10e-9 * np.cos(2 * np.pi * f0 * t)
    meta = dict(sample_rate_hz=fs, spring_constant_n_per_m=40.0, quality_factor=400.0,
                resonance_frequency_hz=f0)
    series = Trace(np.array([x, x]), drive_frequency_hz=f0, gap_m=np.array([12e-9, 8e-9]),
                   **meta)
    sweep = Trace(np.array([x, x]), drive_frequency_hz=np.array([f0, 1.01 * f0]),
                  gap_m=12e-9, **meta)
    assert predict_trace(series, module, run)["summary"]["threshold"] == pytest.approx(
        cal_steady.threshold)
    assert predict_trace(sweep, module, run)["summary"]["threshold"] == pytest.approx(
        cal_all.threshold)
    assert cal_steady.threshold < cal_all.threshold   # a higher rate, a lower threshold
