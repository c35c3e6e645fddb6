"""scripts/calibrate.py on the Nanosurf thermal tune (f0 against the vendor's header, the
result in calibration.json taken by convert.py), and one line + exit 2 on bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from afmlearn.io import read_trace

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
NID = DATA / "nanosurf_thermal_tune" / "thermal.nid"
IBW = DATA / "asylum_am_approach_curves" / "AZ_0052.ibw"


def test_nanosurf_calibration_and_convert_takes_it(tmp_path, run_script):
    out = tmp_path / "cal"
    code, stdout, err = run_script("calibrate.py", f"spectrum={NID}", f"out_dir={out}",
                                   "compare=false")
    assert code == 0, err
    cal = json.loads((out / "calibration.json").read_text())
    assert (out / "thermal_fit.png").stat().st_size > 10_000
    # goal: f0 within 0.1 % of the vendor's header (179.8 kHz)
    assert abs(cal["resonance_frequency_hz"] / 179.8e3 - 1) < 1e-3
    for name in ("resonance_frequency_hz", "quality_factor", "spring_constant_n_per_m"):
        lo, hi = cal[f"{name}_interval"]
        assert lo < cal[name] < hi
    # the window is inferred from the data: neighbouring bins uncorrelated -> rectangular
    assert cal["window"]["name"] == "rectangular" and not cal["window"]["stated_by_file"]
    assert cal["temperature_k"] == pytest.approx(313.15)
    assert cal["correction"]["factor"] == 0.817
    # thermal k (optical lever, 0.817): ~9 N/m; plain equipartition (C = 1) ~11 N/m
    assert 7 < cal["spring_constant_n_per_m"] < 11
    assert cal["equipartition_k_n_per_m"] == pytest.approx(
        cal["spring_constant_n_per_m"] / 0.817, rel=1e-6)
    code, _, err = run_script("convert.py", f"input={IBW}", f"output={tmp_path / 'c.h5'}",
                              f"calibration={out / 'calibration.json'}")
    assert code == 0, err
    trace = read_trace(tmp_path / "c.h5")
    assert trace.quality_factor == pytest.approx(cal["quality_factor"])
    assert trace.spring_constant_n_per_m == pytest.approx(cal["spring_constant_n_per_m"])


@pytest.mark.parametrize("kind", ["missing", "not_a_spectrum", "truncated", "bad_correction",
                                  "flipped_spectrum"])
def test_bad_input_exits_2_with_one_line(kind, tmp_path, run_script):
    args = [f"out_dir={tmp_path / 'o'}", "figures=false", "compare=false"]
    if kind == "missing":
        args.append(f"spectrum={tmp_path / 'none.nid'}")
    elif kind == "not_a_spectrum":
        args.append(f"spectrum={IBW}")
    elif kind == "truncated":
        bad = tmp_path / "t.nid"
        bad.write_bytes(NID.read_bytes()[:30_000])
        args.append(f"spectrum={bad}")
    elif kind == "flipped_spectrum":
        # bytes of the measured spectrum inside the fit range inverted: values < 0 or not finite
        data = bytearray(NID.read_bytes())
        for i in range(16_000, 20_000):
            data[i] ^= 0xFF
        bad = tmp_path / "f.nid"
        bad.write_bytes(bytes(data))
        args.append(f"spectrum={bad}")
    else:
        shutil.copy(NID, tmp_path / "ok.nid")
        args += [f"spectrum={tmp_path / 'ok.nid'}", "correction=sader"]
    line = run_script.error_line("calibrate.py", *args)
    if kind == "flipped_spectrum":
        assert "negative or non-finite" in line, line
