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


def test_printed_verdict_has_no_python_none_and_no_edge_exponent(tmp_path, trace_path,
                                                                 run_script, monkeypatch):
    """What scripts/diagnose.py prints from a report whose numbers were not computed (JSON
    null) and whose exponent profile is not bounded (the audit's single orbit): "n/a", never
    ``None`` or a crash, and the exponent the equations use (1.5, fixed), never the free
    fit's edge value 1.00 as if measured."""
    import afmlearn.diagnose.report as report

    equation = "x'' + 0.002257 x' + 1 x = ...;  F_ts = - 2.772e-05 z^-2 + 5.195 delta^1.5"
    model = {"equation": equation, "heldout_nrmse": None,
             "parameters": {"contact_exponent": 1.5}}
    rec = {"cause": "none", "confidence": 1.0, "gain": None,
           "causes": [{"cause": "viscoelastic", "gain": None},
                      {"cause": "long_range_damping", "gain": 0.2}],
           "baseline": model, "extended": model, "warnings": [],
           "contact_exponent": {"exponent": 1.0000000060705916, "interval_95": [1.0, 3.5],
                                "bounded": False}}
    monkeypatch.setattr(report, "diagnose_trace", lambda *a, **k: rec)
    code, out, err = run_script("diagnose.py", f"trace={trace_path}",
                                f"out_dir={tmp_path / 'o'}", "figures=false")
    assert code == 0, err
    assert "None" not in out and "n/a (not computed)" in out
    line = next(ln for ln in out.splitlines() if ln.startswith("exponent"))
    assert "1.5 (the sphere's), fixed in the equations" in line and "1.00-3.50" in line
    assert not line.split()[1].startswith("1.00")
