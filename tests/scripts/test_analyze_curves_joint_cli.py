"""scripts/analyze_curves.py joint=true: one law fitted jointly per set of curves of a folder."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]


def simulated(path: Path, *overrides: str) -> Path:
    GlobalHydra.instance().clear()  # the entry point run in this process leaves it set
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[*overrides, "progress=false", f"output={path}"])
    simulate(cfg)
    return path


def test_joint_needs_a_folder(tmp_path, run_script):
    path = tmp_path / "curve.h5"
    path.write_bytes(b"x")
    line = run_script.error_line("analyze_curves.py", f"trace={path}", "joint=true",
                                 f"out_dir={tmp_path}/o")
    assert "joint=true needs a folder" in line


@pytest.mark.slow
def test_joint_run_on_a_folder_of_two_free_amplitudes(tmp_path, run_script):
    """Two simulated DMT curves of one tip (free amplitude 1.5 and 2.5 L_ref) in a sub-folder:
    one set, report with the section 3 keys and figures, summary with the set's cause."""
    for i, ratio in enumerate((1.5, 2.5)):
        simulated(tmp_path / "data" / "tip" / f"c{i}.h5", "scenario=lockin",
                  "scenario.n_periods=600", f"excitation.free_amplitude_ratio={ratio}")
    out = tmp_path / "out"
    code, stdout, _ = run_script("analyze_curves.py", f"trace={tmp_path / 'data'}",
                                 f"out_dir={out}", "joint=true", "group_size=2",
                                 "group_diagnoser.max_evaluations=800", "time_limit_s=null")
    assert code == 0
    summary = json.loads((out / "joint_summary.json").read_text())
    group = summary["groups"]["tip"]
    assert group["n_sets"] == 1 and group["errors"] == 0
    rep = json.loads((out / "tip" / "set_00" / "report.json").read_text())
    for key in ("cause", "confidence", "baseline", "extended", "gain", "candidates", "causes",
                "figures", "group"):
        assert key in rep
    assert sorted(rep["input"]) == ["c0.h5", "c1.h5"]
    assert rep["cause"] == "none"   # plain DMT: nothing to extend
    for fig in rep["figures"]:
        assert (out / "tip" / "set_00" / fig).is_file()
    assert "tip: none" in stdout
