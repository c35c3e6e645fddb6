"""scripts/identify.py end to end, and one clear non-zero exit per kind of bad input."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from afmlearn.io import read_trace
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]
SMALL = ["scenario.n_periods=30", "scenario.samples_per_period=100", "noise.level=0.005",
         "free_trace_periods=5", "progress=false"]


def run_identify(tmp: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run([sys.executable, str(ROOT / "scripts" / "identify.py"), *args],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def trace_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "trace.h5"
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[*SMALL, f"output={path}"])
    simulate(cfg)
    return path


def test_identify_writes_result_and_aligned_force(tmp_path, trace_path):
    out = tmp_path / "out"
    proc = run_identify(tmp_path, f"trace={trace_path}", f"out_dir={out}", "identifier=fast",
                        "figures=false")  # figures: tests/afmlearn/identify
    assert proc.returncode == 0, proc.stderr
    assert "x'' +" in proc.stdout and "F_ts" in proc.stdout
    res = json.loads((out / "result.json").read_text())
    assert res["input"] == str(trace_path.resolve())
    trace = read_trace(trace_path)
    with h5py.File(out / "force.h5", "r") as f:
        force = f["force_n"][()]
        assert f["force_lo_n"].shape == f["force_hi_n"].shape == trace.deflection_m.shape
        # the exponent is fixed (below): force.h5 holds the quoted law, the fitted one beside
        quoted, fixed_p = f.attrs["equation"], float(f.attrs["exponent_fixed"])
        assert f["fitted_force_n"].shape == force.shape
        lo, hi = f["force_lo_n"][()], f["force_hi_n"][()]
    assert force.shape == trace.deflection_m.shape
    assert np.isfinite(force).mean() > 0.9
    # a tapping trace: repulsive peaks of nN size (simulated peak ~ 10 nN), some attraction
    assert 0.1e-9 < np.nanmax(force) < 1e-6
    assert res["summary"]["peak_repulsive_force_n"] == pytest.approx(np.nanmax(force))
    assert (out / "model.json").exists() and not list(out.glob("*.png"))
    assert (out / ".hydra" / "config.yaml").exists()
    # 30 periods of one orbit do not bound the contact exponent (physics: one indentation
    # depth); the equation printed and stored is the law at the sphere's 1.5, re-fitted there
    summary = res["summary"]
    assert summary["interaction_exponent_bounded"] is False
    fixed = res["exponent_fixed"]
    assert fixed["exponent"] == 1.5 and summary["interaction_exponent_fixed"] == 1.5
    assert res["equation"] == fixed["equation"] == quoted and fixed_p == 1.5
    ok = np.isfinite(lo) & np.isfinite(force)
    assert ok.mean() > 0.9 and np.all(lo[ok] <= force[ok] + 1e-15)
    assert np.all(force[ok] <= hi[ok] + 1e-15)
    assert re.search(r"delta\^1\.5(?![0-9])", res["equation"])
    assert re.search(r"delta\^1\.5(?![0-9])", res["equation_si"])
    # the refit is a fit: inside the 95 % profile interval (rise below 3.84), a0 in range
    assert -1.0 < fixed["profile_rise"] < 3.841
    assert 0 < fixed["a0"] <= 1
    lines = proc.stdout.splitlines()
    assert lines[0] == res["equation"]
    line = next(ln for ln in lines if ln.startswith("interaction exponent"))
    assert line.startswith("interaction exponent 1.5 FIXED") and "not identifiable" in line
    assert "0.50-4.00" in line  # the unbounded interval stays in the text
    assert "None" not in proc.stdout


def _copy(src: Path, dst: Path, edit) -> Path:
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


def _clip(f: h5py.File) -> None:
    d = f["deflection_m"][()]
    f["deflection_m"][...] = np.minimum(d, 0.9 * d.max())


def _nan(f: h5py.File) -> None:
    d = f["deflection_m"][()]
    d[100:105] = np.nan
    f["deflection_m"][...] = d


def _undersample(f: h5py.File) -> None:
    f.attrs["sample_rate_hz"] = 15.0 * f.attrs["drive_frequency_hz"]


BAD = {
    "missing_calibration": (lambda f: f.attrs.__delitem__("spring_constant_n_per_m"),
                            "spring_constant_n_per_m"),
    # a recorded file cannot be resampled into more harmonics: say what to record
    "undersampled": (_undersample, "record at a higher sample rate"),
    "clipped": (_clip, "clip"),
    "nan": (_nan, "NaN"),
}


def test_bad_input_subprocess_exit_status(tmp_path, trace_path):
    """The real process: status 2 and a one-line message, no traceback."""
    edit, needle = BAD["missing_calibration"]
    bad = _copy(trace_path, tmp_path / "bad.h5", edit)
    proc = run_identify(tmp_path, f"trace={bad}", f"out_dir={tmp_path / 'out'}",
                        "identifier=fast")
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0], proc.stderr
    assert not (tmp_path / "out" / "result.json").exists()


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_exits_non_zero_with_a_clear_message(tmp_path, trace_path, case, run_script):
    """Each kind of bad input (scripts/identify.py main run in-process: imports paid once)."""
    edit, needle = BAD[case]
    bad = _copy(trace_path, tmp_path / "bad.h5", edit)
    out = tmp_path / "out"
    line = run_script.error_line("identify.py", f"trace={bad}", f"out_dir={out}",
                                 "identifier=fast")
    assert needle.lower() in line.lower(), line
    assert not (out / "result.json").exists()
    if case == "undersampled":  # the rate it takes, and the parameter of a simulation
        assert "15 samples per drive period" in line and "at least 20 are needed" in line
        assert "scenario.samples_per_period" in line and "Hz" in line


def test_missing_file(tmp_path, run_script):
    line = run_script.error_line("identify.py", f"trace={tmp_path / 'nope.h5'}",
                                 f"out_dir={tmp_path / 'o'}")
    assert "nope.h5" in line


@pytest.mark.slow
def test_series_file_all_rows_jointly_and_bad_row(tmp_path, run_script):
    """A set-point series: every row jointly by default (the exponent line is printed);
    an out-of-range `row` is one clear error line with exit status 2."""
    path = tmp_path / "series.h5"
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[
            "scenario=spectroscopy", "scenario.gap_ratios=[0.9,0.7,0.5]",
            "scenario.n_periods=30", "scenario.samples_per_period=100",
            "cantilever.quality_factor=120", "noise.level=0.002", "free_trace_periods=5",
            "progress=false", f"output={path}"])
    simulate(cfg)
    line = run_script.error_line("identify.py", f"trace={path}", f"out_dir={tmp_path / 'bad'}",
                                 "row=7", "figures=false")
    assert line.startswith("error: row must be null")
    out = tmp_path / "out"
    proc = run_identify(tmp_path, f"trace={path}", f"out_dir={out}", "identifier=fast",
                        "figures=true", "identifier.refine=false")
    assert proc.returncode == 0, proc.stderr
    assert "interaction exponent" in proc.stdout or "no contact term" in proc.stdout
    res = json.loads((out / "result.json").read_text())
    assert res["joint"]["n_observations"] == 3
    # 3 short set-points of one free amplitude: the equation never quotes an unbounded
    # exponent at its profile value (the audit's "delta^3.84114", interval 0.50-4.00)
    summary = res["summary"]
    if summary.get("interaction_exponent_bounded") is False:
        fixed = res["exponent_fixed"]
        assert fixed is not None and fixed["text"] in proc.stdout
        if fixed.get("equation"):
            assert res["equation"] == fixed["equation"]
            with h5py.File(out / "force.h5", "r") as f:  # the quoted law's force and band
                assert f.attrs["equation"] == res["equation"] and "fitted_force_n" in f
            assert re.search(r"delta\^1\.5(?![0-9])", res["equation"])
        else:
            assert "NOT an identified exponent" in fixed["text"] or fixed["exponent"] is None
    assert (out / "force.png").exists()


def test_summary_values_print_without_python_none() -> None:
    """A value the pipeline does not compute for the input (a joint fit's held-out state
    accuracy) is said so, not printed as ``None``; per-observation lists element by element."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        from identify import _shown
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    assert _shown(None) == "n/a (not computed for this input)"
    shown = _shown([1.3402063609418025e-26, -1.6255220096485468e-24])
    assert shown == "[1.34021e-26, -1.62552e-24]"
    assert _shown(7.96279e-09) == "7.96279e-09"
