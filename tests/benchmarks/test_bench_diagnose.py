"""The diagnosis benchmark's statistics on cases with a known answer: the null-calibrated
thresholds (empirical quantile, floored at the chi-square point) and the one-sided
Clopper--Pearson bound of the null check."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_diagnose import (  # noqa: E402
    _draw_key,
    _parse_variant,
    calibrate,
    interval,
    null_count,
    series_calibrate,
    series_title,
    share,
    upper_bound,
)


def test_null_count_reads_the_traces_not_the_causes():
    # the source text of a calibration says "over 7 causes" before "over 60 null traces"
    recs = [_null({"higher_mode": float(i), "viscoelastic": 0.0}) for i in range(60)]
    assert null_count(calibrate(recs, family_rate=0.05).source) == 60
    assert null_count("shipped defaults") == 0


def _null(drops: dict[str, float]) -> dict:
    return {"spp": 200, "noise": 0.01,
            "candidates": [{"cause": c, "delta_chi2": d} for c, d in drops.items()]}


def test_threshold_is_the_null_quantile_or_the_chi2_point():
    # 101 nulls, higher_mode drops 0..100: at level 0.7 / 7 = 0.1 the 0.9 quantile is 90
    # exactly; the other causes never drop, so they sit at their chi-square 0.9 points
    recs = [_null({"higher_mode": float(i), "viscoelastic": 0.0, "long_range_damping": 0.0,
                   "contact_geometry": 0.0, "adhesion_hysteresis": 0.0, "electrostatic": 0.0,
                   "detector_nonlinearity": 0.0}) for i in range(101)]
    cal = calibrate(recs, family_rate=0.7)
    assert cal.thresholds["higher_mode"] == pytest.approx(90.0)
    assert cal.thresholds["viscoelastic"] == pytest.approx(2.71, abs=0.005)       # 1 dof
    assert cal.thresholds["long_range_damping"] == pytest.approx(4.61, abs=0.005)  # 2 dof
    assert cal.thresholds["contact_geometry"] == pytest.approx(2.71, abs=0.005)
    assert "101 null traces" in cal.source


def test_one_sided_bound_with_no_false_cause_is_the_rule_of_three_exact_form():
    # 0 of n: the bound solves (1 - p)^n = 0.05
    for n in (20, 30, 40):
        assert upper_bound(0, n) == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-9)
    assert upper_bound(0, 40) == pytest.approx(0.072, abs=5e-4)
    assert upper_bound(3, 3) == 1.0
    # more false causes in the same number of nulls: a larger bound
    assert upper_bound(0, 30) < upper_bound(1, 30) < upper_bound(2, 30)


def test_two_sided_interval_has_the_exact_clopper_pearson_ends():
    # 0 of n: [0, 1 - 0.025^(1/n)]; n of n mirrors it; k of n mirrors n - k of n
    for n in (3, 10, 20):
        lo, hi = interval(0, n)
        assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / n), rel=1e-9)
        assert interval(n, n) == pytest.approx((0.025 ** (1 / n), 1.0), rel=1e-9)
    for k in range(11):
        lo, hi = interval(k, 10)
        assert lo < k / 10 < hi or k in (0, 10)
        assert (lo, hi) == pytest.approx(tuple(1 - x for x in interval(10 - k, 10)[::-1]))
    # 9 of 10 right does not show a 90 % share at 95 %: the interval reaches down to 55.5 %
    assert interval(9, 10)[0] == pytest.approx(0.555, abs=5e-4)
    assert share(9, 10) == "9/10 = 90 % [55-100]"


def test_variants_name_the_rows_and_the_design():
    assert _parse_variant("8:phase") == (8, True, "one")
    assert _parse_variant("1:none") == (1, False, "one")
    assert _parse_variant("2x4:phase") == (8, True, "two")       # both amplitudes, 4 rows each
    assert _parse_variant("twin:none") == (8, False, "twin")
    for bad in ("3:phase", "8:yes", "8"):
        with pytest.raises(ValueError, match="--variants"):
            _parse_variant(bad)


def test_two_amplitude_runs_have_their_own_title():
    two = [_parse_variant("2x4:phase"), _parse_variant("twin:phase")]
    assert "two-free-amplitude" in series_title(two)
    assert "two-free-amplitude" not in series_title([*two, _parse_variant("8:phase")])
    assert "two-free-amplitude" not in series_title([_parse_variant("8:phase")])


def test_draw_keys_keep_old_records_and_separate_the_designs():
    job = {"set_id": 3, "spp": 200, "noise": 0.01, "cause": "electrostatic", "index": 4,
           "seed": 2027, "periods": 30.0}
    old = _draw_key(job)                                   # a record before designs existed
    assert old == (3, 200, 0.01, "electrostatic", 4, 2027, 30.0)
    assert _draw_key({**job, "design": "one"}) == old
    keys = {_draw_key({**job, "design": d}) for d in ("one", "two", "twin")}
    assert len(keys) == 3


def test_no_phase_calibration_writes_its_own_section(tmp_path, monkeypatch):
    """``--calibrate --no-phase`` reads the no-phase null records (set_id 7, phase False) and
    writes the ``series_nophase`` section with its provenance; the recorded-phase ``series``
    section stays as it was."""
    import bench_diagnose

    cal_file = tmp_path / "null_calibration.json"
    series = {"thresholds": {"viscoelastic": 2.0}, "min_gain": 0.05, "source": "ser"}
    cal_file.write_text(json.dumps({"thresholds": {"viscoelastic": 1.0}, "min_gain": 0.05,
                                    "series": series}))
    monkeypatch.setattr(bench_diagnose, "CALIBRATION", cal_file)
    causes = ("higher_mode", "viscoelastic", "long_range_damping", "contact_geometry",
              "adhesion_hysteresis", "electrostatic", "detector_nonlinearity")
    n = 40
    with (tmp_path / "series_null_nophase.jsonl").open("w") as f:
        for i in range(n):        # viscoelastic drops 0..39 on the nulls, the others nothing
            rec = {"set_id": 7, "spp": 200, "noise": 0.01, "cause": "none", "index": i,
                   "seed": 2026, "periods": 30.0, "n_points": 8, "phase": False,
                   "design": "one", "commit": "abc1234567", "cause_found": "none",
                   "candidates": [{"cause": c, "delta_chi2": float(i) if c == "viscoelastic"
                                   else 0.0} for c in causes]}
            f.write(json.dumps(rec) + "\n")
    args = argparse.Namespace(design="one", no_phase=True, null=n, seed=2026, periods=30.0,
                              report_only=True, since="", keep_thresholds=False,
                              family_rate=0.7, no_doc=False, workers=1)
    assert series_calibrate(args, [(200, 0.01)], tmp_path) == 0
    d = json.loads(cal_file.read_text())
    assert d["series"] == series
    sec = d["series_nophase"]
    prov = sec["provenance"]
    assert prov["set_id"] == 7 and prov["drive_phase"] is False
    assert prov["n_null_series"] == n and prov["draws"] == [0, n - 1]
    assert "drive phase not recorded" in sec["source"]
    # level 0.7 / 7 = 0.1: the 0.9 quantile of 0..39 (linear interpolation) is 35.1
    assert sec["thresholds"]["viscoelastic"] == pytest.approx(35.1)
