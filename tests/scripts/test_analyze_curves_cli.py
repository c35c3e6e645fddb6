"""scripts/analyze_curves.py: a simulated lock-in curve end to end, one-line exit 2 on bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "analyze_curves.py"


def simulated(path: Path, *overrides: str) -> Path:
    GlobalHydra.instance().clear()  # the entry point run in this process leaves it set
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[*overrides, "progress=false", f"output={path}"])
    simulate(cfg)
    return path


@pytest.fixture(scope="module")
def curve_path(tmp_path_factory) -> Path:
    return simulated(tmp_path_factory.mktemp("curves") / "curve.h5", "scenario=lockin",
                     "scenario.n_periods=600", "excitation.free_amplitude_ratio=1.5")


@pytest.fixture(scope="module")
def steady_path(tmp_path_factory) -> Path:
    """A steady deflection trace (not a lock-in curve), made before any entry point runs."""
    return simulated(tmp_path_factory.mktemp("steady") / "steady.h5", "scenario.n_periods=5",
                     "free_trace=false")


@pytest.mark.parametrize("case", ["missing", "not_hdf5", "not_a_curve"])
def test_bad_input_exits_2_with_one_line(tmp_path, run_script, steady_path, case):
    if case == "missing":
        path = tmp_path / "nope.h5"
    elif case == "not_hdf5":
        path = tmp_path / "junk.h5"
        path.write_bytes(b"not an hdf5 file")
    else:
        path = steady_path
    run_script.error_line("analyze_curves.py", f"trace={path}", f"out_dir={tmp_path}/o")


def test_folder_of_damaged_files_exits_2_with_one_line(tmp_path, run_script):
    folder = tmp_path / "damaged"
    (folder / "On_Surface").mkdir(parents=True)
    (folder / "On_Surface" / "a.ibw").write_bytes(b"not an igor wave")
    (folder / "b.h5").write_bytes(b"not an hdf5 file")
    line = run_script.error_line("analyze_curves.py", f"trace={folder}",
                                 f"out_dir={tmp_path}/o", "figures=false")
    assert "none of the 2 curve files" in line
    # the per-file errors are still listed
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["n_analysed"] == 0 and len(summary["curves"]) == 2
    assert all("error" in r for r in summary["curves"])


@pytest.mark.slow
def test_simulated_curve_end_to_end(tmp_path, curve_path):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(SCRIPT), f"trace={curve_path}",
                           f"out_dir={out}"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr
    stdout = proc.stdout
    report = json.loads((out / "report.json").read_text())
    for key in ("cause", "confidence", "baseline", "extended", "gain", "candidates", "causes",
                "figures", "curve"):
        assert key in report
    assert report["cause"] == "none"  # plain DMT: nothing to extend
    assert 0.0 <= report["confidence"] <= 1.0
    for fig in report["figures"]:
        assert (out / fig).is_file()
    assert "cause: none" in stdout
