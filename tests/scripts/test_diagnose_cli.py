"""scripts/diagnose.py end to end (subprocess, as a user runs it) and its bad-input exits."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from afmlearn.diagnose.synthetic import hidden_trace

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def trace_path(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("dcli") / "recording.h5"
    hidden_trace(np.random.default_rng([12, 77]), path, cause="none", samples_per_period=100,
                 n_periods=120)
    return path


def test_diagnose_cli_writes_report(tmp_path, trace_path):
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "diagnose.py"),
                           f"trace={trace_path}", f"out_dir={out}", "figures=false"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    rep = json.loads((out / "report.json").read_text())
    assert rep["cause"] in {"none", *[c["cause"] for c in rep["candidates"]]}
    assert "cause" in proc.stdout and "report.md" in proc.stdout
    assert (out / "report.md").exists() and (out / ".hydra" / "config.yaml").exists()


@pytest.mark.parametrize("args, needle", [
    (("trace=/nonexistent/file.h5",), "no such file"),
    (("diagnoser.heldout_fraction=0.9",), "heldout_fraction"),
    (("row=3",), "row"),
])
def test_bad_input_exits_2(tmp_path, trace_path, run_script, args, needle):
    base = [f"trace={trace_path}", f"out_dir={tmp_path / 'o'}", "figures=false"]
    over = {a.split("=")[0] for a in args}
    line = run_script.error_line("diagnose.py",
                                 *[a for a in base if a.split("=")[0] not in over], *args)
    assert needle in line, line
