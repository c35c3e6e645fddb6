"""scripts/analyze_force_curve.py on the three real static curves (numbers of docs/real_data.md),
on a converted force-curve file, and one line + exit 2 on a file that holds no static curve."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FORCE = ROOT / "tests" / "data" / "afmformats_forcecurves"
SIN = FORCE / "fmt-igor-fd_SiN_FD_plot.ibw"
JPK = FORCE / "fmt-jpk-fd_spot3-0192.jpk-force"
LOCKIN = ROOT / "tests" / "data" / "asylum_am_approach_curves" / "AZ_0052.ibw"


def test_real_curve_report_and_converted_file_agree(tmp_path, run_script):
    code, out, err = run_script("analyze_force_curve.py", f"curve={SIN}",
                                f"out_dir={tmp_path / 'a'}")
    assert code == 0, err
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    # docs/real_data.md: free exponent 1.15, retraction NRMSE 0.0135 -> 0.0147, pull-off 12.8 nN
    assert report["extended"]["exponent"] == pytest.approx(1.15, abs=0.05)
    assert report["baseline"]["exponent"] == 1.5
    assert report["pull_off_n"] == pytest.approx(12.8e-9, rel=0.02)
    assert report["pull_off_n"] > 3 * report["jump_in_n"] and report["loop_work_j"] > 0
    assert report["spring_constant_n_per_m"] == pytest.approx(1.184, abs=1e-3)
    assert "gain" in out and "pull-off 12.8" in out
    # the same curve through scripts/convert.py gives the same report
    code, _, err = run_script("convert.py", f"input={JPK}", f"output={tmp_path / 'j.h5'}")
    assert code == 0, err
    for name, curve in (("direct", JPK), ("converted", tmp_path / "j.h5")):
        code, _, err = run_script("analyze_force_curve.py", f"curve={curve}",
                                  f"out_dir={tmp_path / name}")
        assert code == 0, err
    direct, converted = (json.loads((tmp_path / n / "report.json").read_text())
                         for n in ("direct", "converted"))
    assert converted["gain"] == pytest.approx(direct["gain"], rel=1e-9)
    assert converted["extended"]["exponent"] == direct["extended"]["exponent"]


def test_not_a_static_curve_exits_2_with_one_line(tmp_path, run_script):
    line = run_script.error_line("analyze_force_curve.py", f"curve={LOCKIN}",
                                 f"out_dir={tmp_path / 'o'}")
    assert "holds no static force curve" in line
    line = run_script.error_line("analyze_force_curve.py", f"curve={SIN}", "index=3",
                                 f"out_dir={tmp_path / 'o'}")
    assert "index must be in [0, 0]" in line
