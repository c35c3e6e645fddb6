"""scripts/convert.py: real files convert; every damaged or uncalibrated input ends with exit
status 2 and exactly one line (damaged copies of the real files made in tmp_path)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from afmlearn.io import read_trace

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
SCRIPT = ROOT / "scripts" / "convert.py"
IBW = DATA / "asylum_am_approach_curves" / "AZ_0052.ibw"
JPK = DATA / "afmformats_forcecurves" / "fmt-jpk-fd_spot3-0192.jpk-force"
STATIC = DATA / "afmformats_forcecurves" / "fmt-igor-fd_SiN_FD_plot.ibw"


def test_convert_ibw_to_trace_and_static_curve(tmp_path, run_script):
    code, out, err = run_script("convert.py", f"input={IBW}", f"output={tmp_path / 'a.h5'}",
                         "quality_factor=200")
    assert code == 0, err
    trace = read_trace(tmp_path / "a.h5")
    assert trace.quality_factor == 200.0 and trace.is_curves
    code, out, err = run_script("convert.py", f"input={STATIC}", f"output={tmp_path / 's.h5'}")
    assert code == 0 and "force_curve" in out


def _truncated(src: Path, dst: Path, keep: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * keep)])
    return dst


def _flipped(src: Path, dst: Path, start: int, stop: int) -> Path:
    data = bytearray(src.read_bytes())
    for i in range(start, min(stop, len(data))):
        data[i] ^= 0xFF
    dst.write_bytes(bytes(data))
    return dst


def _damaged(kind: str, tmp: Path) -> tuple[Path, list[str], str]:
    """A damaged input, extra arguments and a fragment the error line must contain."""
    if kind == "empty":
        p = tmp / "empty.ibw"
        p.write_bytes(b"")
        return p, [], "empty file"
    if kind == "unknown_format":
        p = tmp / "curve.xyz"
        shutil.copy(IBW, p)
        return p, [], "unknown file format"
    if kind == "wrong_extension_ibw_as_jpk":
        p = tmp / "curve.jpk-force"
        shutil.copy(IBW, p)
        return p, [], "cannot be read"
    if kind == "wrong_extension_jpk_as_ibw":
        p = tmp / "curve.ibw"
        shutil.copy(JPK, p)
        return p, [], "cannot be read"
    if kind == "wrong_extension_nid_as_csv":
        p = tmp / "tune.csv"
        shutil.copy(DATA / "nanosurf_thermal_tune" / "thermal.nid", p)
        return p, [], "binary content, not a text CSV"
    if kind == "truncated_ibw":
        return _truncated(IBW, tmp / "t.ibw", 0.5), [], "cannot be read"
    if kind == "truncated_jpk":
        return _truncated(JPK, tmp / "t.jpk-force", 0.6), [], "cannot be read"
    if kind == "flipped_ibw_header":
        return _flipped(IBW, tmp / "f.ibw", 0, 64), [], "cannot be read"
    if kind == "flipped_ibw_data":  # the Amp column's bytes inverted (offset 384 + 2181*4)
        return _flipped(IBW, tmp / "d.ibw", 9200, 11000), [], "d.ibw"
    if kind == "flipped_jpk":
        return _flipped(JPK, tmp / "f.jpk-force", 0, 200), [], "cannot be read"
    if kind == "missing_calibration":
        p = tmp / "series.csv"
        np.savetxt(p, np.zeros((50, 1)), header="# sample_rate_hz: 1e6\ndeflection_nm",
                   comments="")
        return p, [], "missing calibration 'spring_constant_n_per_m'"
    if kind == "wrong_units":
        p = tmp / "series.csv"
        np.savetxt(p, np.full((50, 1), 25.0), header="deflection_m", comments="")
        return p, [], "not a length an AFM records in metres"
    if kind == "bad_calibration_json":
        p = tmp / "cal.json"
        p.write_text("{not json")
        return IBW, [f"calibration={p}"], "not a readable calibration JSON"
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", [
    "empty", "unknown_format", "wrong_extension_ibw_as_jpk", "wrong_extension_jpk_as_ibw",
    "wrong_extension_nid_as_csv",
    "truncated_ibw", "truncated_jpk", "flipped_ibw_header", "flipped_ibw_data", "flipped_jpk",
    "missing_calibration", "wrong_units", "bad_calibration_json"])
def test_bad_input_exits_2_with_one_line(kind, tmp_path, run_script):
    path, extra, fragment = _damaged(kind, tmp_path)
    out_file = tmp_path / "out.h5"
    line = run_script.error_line("convert.py", f"input={path}", f"output={out_file}", *extra)
    assert fragment in line, line
    assert not out_file.exists()


def test_damaged_file_in_a_fresh_process_prints_exactly_one_line(tmp_path):
    """Through a real process (Hydra's logging set up): parsers' own log lines stay silent."""
    import os
    import subprocess

    bad = _truncated(IBW, tmp_path / "t.ibw", 0.3)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, str(SCRIPT), f"input={bad}",
                           f"output={tmp_path / 'o.h5'}"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
