"""scripts/diagnose.py on several files of one tip (``trace=[a.h5,b.h5]``): one experiment,
one report; inconsistent lists exit 2 with one line."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from afmlearn.diagnose.synthetic import draw_series_case, series_files, simulate_series
from afmlearn.io import read_trace, write_trace


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A null series at two free amplitudes, 2 set-points each (small and fast)."""
    folder = tmp_path_factory.mktemp("dfiles")
    case = draw_series_case(np.random.default_rng([5, 2]), causes="none", n_points=4,
                            free_amplitudes=2)
    paths = series_files(simulate_series(case, folder / "exp", samples_per_period=60,
                                         n_periods=8, free_periods=4))
    other = folder / "other-lever.h5"                  # the same rows, another cantilever
    tr = read_trace(paths[1])
    write_trace(dataclasses.replace(tr, quality_factor=tr.quality_factor * 1.5), other)
    return paths, other


def test_two_files_are_one_experiment(tmp_path, files, run_script):
    paths, _ = files
    out = tmp_path / "out"
    code, stdout, err = run_script("diagnose.py", f"trace=[{paths[0]},{paths[1]}]",
                                   f"out_dir={out}", "figures=false",
                                   "diagnoser.hypotheses=[{_target_:afmlearn.diagnose."
                                   "hypotheses.Electrostatic}]")
    assert code == 0, err
    rep = json.loads((out / "report.json").read_text())
    assert rep["input"] == [str(p.resolve()) for p in paths]
    # every row of both files, each with its own rest gap
    gaps = np.concatenate([read_trace(p).gap_m for p in paths])
    assert np.allclose(sorted(o["gap_m"] for o in rep["observations"]), sorted(gaps),
                       rtol=1e-12)
    assert "cause" in stdout


@pytest.mark.parametrize("which, extra, needle", [
    ("other", (), "quality_factor"),
    ("both", ("row=1",), "row must be null"),
    ("none", (), "non-empty list"),
])
def test_bad_lists_exit_2(tmp_path, files, run_script, which, extra, needle):
    paths, other = files
    trace = {"other": f"[{paths[0]},{other}]", "both": f"[{paths[0]},{paths[1]}]",
             "none": "[]"}[which]
    line = run_script.error_line("diagnose.py", f"trace={trace}", f"out_dir={tmp_path}",
                                 "figures=false", *extra)
    assert needle in line, line
