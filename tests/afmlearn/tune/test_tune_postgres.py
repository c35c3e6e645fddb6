"""Two worker processes of one study on a real PostgreSQL server on loopback (conftest)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import optuna

from afmlearn.tune import FINISHED

TOY = Path(__file__).parents[2] / "hydra_plugins" / "app" / "toy.py"


def test_two_workers_share_postgresql(tmp_path: Path, postgres_url: str) -> None:
    marks = tmp_path / "marks"
    cmd = [sys.executable, str(TOY), "-m", f"hydra.sweeper.storage={postgres_url}",
           "hydra.sweeper.study_name=toy_pg", "hydra.sweeper.n_trials=6",
           "hydra.sweeper.n_jobs=2", "sleep_s=3.0", f"marker_dir={marks}"]
    done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert done.returncode == 0, done.stderr[-2000:]
    study = optuna.load_study(study_name="toy_pg", storage=postgres_url)
    finished = study.get_trials(states=FINISHED)
    assert len(finished) == 6
    assert len({tuple(sorted(t.params.items())) for t in finished}) == 6
    assert len({p.stem.split("-")[0] for p in marks.glob("*.done")}) == 2  # two processes
    # the same command again: the study is complete, nothing runs
    again = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                           env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert again.returncode == 0, again.stderr[-2000:]
    assert len(list(marks.glob("*.start"))) == 6
    assert len(optuna.load_study(study_name="toy_pg", storage=postgres_url).trials) == 6
