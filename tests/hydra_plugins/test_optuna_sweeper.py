"""The Optuna sweeper end to end on a toy task: resume after SIGKILL, two workers, bad input."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import optuna
import pytest
from optuna.trial import TrialState

from afmlearn.tune import FINISHED

FAST = ("hydra.sweeper.heartbeat_interval=1", "hydra.sweeper.grace_period=3")


def _study(url: str, name: str = "toy") -> optuna.Study:
    return optuna.load_study(study_name=name, storage=url)


def _finished_params(study: optuna.Study) -> list[tuple]:
    return [tuple(sorted(t.params.items())) for t in study.get_trials(states=FINISHED)]


def test_sigkill_mid_trial_then_resume(tmp_path: Path, toy_cmd, run_toy) -> None:
    url = f"sqlite:///{tmp_path / 'toy.db'}"
    marks = tmp_path / "marks"
    args = (f"hydra.sweeper.storage={url}", "hydra.sweeper.n_trials=4", "sleep_s=2.0",
            f"marker_dir={marks}", *FAST)
    proc = subprocess.Popen(toy_cmd(*args), cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True,
                            env={**os.environ, "PYTHONWARNINGS": "ignore"})
    deadline = time.monotonic() + 180
    try:
        while time.monotonic() < deadline:  # kill during the third trial
            starts = {p.stem for p in marks.glob("*.start")}
            dones = {p.stem for p in marks.glob("*.done")}
            if len(dones) == 2 and len(starts - dones) == 1:
                break
            assert proc.poll() is None, "the sweep ended before it could be killed"
            time.sleep(0.1)
        else:
            pytest.fail("the third trial never started")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    study = _study(url)
    states = [t.state for t in study.trials]
    assert states.count(TrialState.COMPLETE) == 2 and states.count(TrialState.RUNNING) == 1
    killed = next(t for t in study.trials if t.state == TrialState.RUNNING)

    done = run_toy(*args)  # the same command resumes
    assert done.returncode == 0, done.stderr[-2000:]
    study = _study(url)
    finished = study.get_trials(states=FINISHED)
    assert len(finished) == 4
    assert study.trials[killed.number].state == TrialState.FAIL
    retry = [t for t in finished if t.system_attrs.get("failed_trial") == killed.number]
    assert len(retry) == 1 and retry[0].params == killed.params  # retried with its parameters
    assert len(set(_finished_params(study))) == 4  # no duplicates
    assert len(list(marks.glob("*.start"))) == 5  # 2 + killed + 1 new + its retry, nothing rerun
    assert "study toy (minimize): 4 complete" in done.stdout


def test_two_workers_share_sqlite(tmp_path: Path, run_toy) -> None:
    url = f"sqlite:///{tmp_path / 'toy.db'}"
    marks = tmp_path / "marks"
    done = run_toy(f"hydra.sweeper.storage={url}", "hydra.sweeper.n_trials=6",
                   "hydra.sweeper.n_jobs=2", "hydra.sweeper.baseline=true", "sleep_s=3.0",
                   f"marker_dir={marks}", *FAST)
    assert done.returncode == 0, done.stderr[-2000:]
    study = _study(url)
    assert len(study.get_trials(states=FINISHED)) == 6
    assert len(set(_finished_params(study))) == 6
    first = study.trials[0]  # the config's own values, queued as the baseline
    assert first.user_attrs.get("baseline") and first.params == {"x": 0.0, "n": 1, "opt": "a"}
    assert first.value == 2.0  # (0 - 1)^2 + 1
    pids = {p.stem.split("-")[0] for p in marks.glob("*.done")}
    assert len(pids) == 2  # both processes ran trials
    best = study.best_trial
    exported = (tmp_path / "tuned" / "experiment" / "toy.yaml").read_text()
    assert f"x: {best.params['x']!r}" in exported


@pytest.mark.parametrize(("override", "needle"), [
    ("not_a_key=interval(0,1)", "'not_a_key' is not a path of the config"),
    ("hydra.sweeper.params.x='glob(a*)'", "x: unsupported distribution"),
    ("hydra.sweeper.params.x='tag(grid, interval(0.0, 1.0))'", "unsupported tag(s) ['grid']"),
])
def test_bad_input_fails_before_any_trial(tmp_path: Path, run_toy, override: str,
                                          needle: str) -> None:
    url = f"sqlite:///{tmp_path / 'toy.db'}"
    done = run_toy(f"hydra.sweeper.storage={url}", override)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert lines[-1].startswith("error: ") and needle in lines[-1], done.stderr[-1000:]
    assert not (tmp_path / "multirun").exists()  # no job ran



def test_pruner_null_switches_pruning_off(tmp_path: Path, run_toy) -> None:
    # the same seeded sweep prunes under a median pruner and prunes nothing with pruner=null
    def pruned(*overrides: str) -> int:
        url = f"sqlite:///{tmp_path / (str(len(overrides)) + '.db')}"
        done = run_toy(f"hydra.sweeper.storage={url}", "hydra.sweeper.n_trials=10", *overrides)
        assert done.returncode == 0, done.stderr[-2000:]
        return len(_study(url).get_trials(states=(TrialState.PRUNED,)))

    assert pruned("hydra.sweeper.pruner=null") == 0
    assert pruned("+hydra.sweeper.pruner._target_=optuna.pruners.MedianPruner",
                  "+hydra.sweeper.pruner.n_startup_trials=2") > 0
