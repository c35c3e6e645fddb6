"""Diagnoser: the report contract, bad input, and a null trace reported as ``none``."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from afmlearn.diagnose import Diagnoser, NullCalibration
from afmlearn.diagnose.diagnoser import name_cause
from afmlearn.diagnose.report import diagnose_trace
from afmlearn.diagnose.synthetic import EFFECT_CAUSES
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


def test_labels_are_never_read(make_trace, tmp_path, monkeypatch):
    """The diagnosis must not open /labels: make any such read fail loudly."""
    path, _ = make_trace("none", 11)
    import afmlearn.io.reader as reader
    real = reader.read_trace

    def guarded(p, *a, labels=False, **kw):
        assert not labels, "diagnosis asked for the labels"
        return real(p, *a, labels=labels, **kw)

    monkeypatch.setattr("afmlearn.diagnose.report.read_trace", guarded)
    diagnose_trace(path, tmp_path / "g")


def test_name_cause_rule():
    # significant needs both the evidence and the gain; the largest penalised evidence wins
    idx, conf = name_cause([50.0, 30.0, 1.0], [0.2, 0.4, 0.9], [10.0, 10.0, 10.0], 0.05)
    assert idx == 0 and 0 < conf < 1
    idx, _ = name_cause([50.0, 45.0], [0.2, 0.4], [30.0, 10.0], 0.05)
    assert idx == 1                     # the threshold penalises the flexible extension
    idx, conf = name_cause([5.0, 30.0], [0.5, 0.01], [10.0, 10.0], 0.05)
    assert idx is None and conf > 0.5


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
