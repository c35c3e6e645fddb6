"""run_worker: a study ends with exactly n_trials finished trials, also with concurrent workers
and with a dead trial that must be retried; SearchSpace parsing and its errors."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import optuna
import pytest
from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution
from optuna.trial import TrialState

from afmlearn.tune import FINISHED, SearchSpace, open_storage, open_study, run_worker

optuna.logging.set_verbosity(optuna.logging.WARNING)


def _objective(trial: optuna.Trial) -> float:
    x = trial.suggest_float("x", -3.0, 3.0)
    time.sleep(0.05)
    return (x - 1.0) ** 2


def test_concurrent_workers_reach_exactly_n_trials(tmp_path: Path) -> None:
    storage = open_storage(f"sqlite:///{tmp_path / 's.db'}", heartbeat_interval=1)
    study = open_study(storage, study_name="s", directions=["minimize"])
    results = []

    def work(index: int) -> None:
        s = optuna.load_study(study_name="s", storage=storage)
        results.append(run_worker(s, _objective, n_trials=7, poll_interval=0.05,
                                  sampler_factory=lambda seed: optuna.samplers.RandomSampler(
                                      seed=seed), worker_index=index))

    threads = [threading.Thread(target=work, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    finished = study.get_trials(states=FINISHED)
    assert len(finished) == 7 == sum(r.complete for r in results)
    assert len({t.params["x"] for t in finished}) == 7  # seeds differ: no repeated draws
    # re-running a finished study does nothing
    again = run_worker(study, _objective, n_trials=7, poll_interval=0.05)
    assert again.complete == 0 and len(study.get_trials(states=FINISHED)) == 7


@pytest.mark.filterwarnings("ignore:Heartbeat of storage")
def test_dead_trial_is_failed_and_retried_with_its_parameters(tmp_path: Path) -> None:
    storage = open_storage(f"sqlite:///{tmp_path / 's.db'}", heartbeat_interval=1,
                           grace_period=2)
    study = open_study(storage, study_name="s", directions=["minimize"])
    dead = study.ask()  # a worker that died mid-trial: RUNNING, one heartbeat, then silence
    x_dead = dead.suggest_float("x", -3.0, 3.0)
    storage.record_heartbeat(dead._trial_id)
    t0 = time.monotonic()
    run_worker(study, _objective, n_trials=3, poll_interval=0.1)
    assert time.monotonic() - t0 >= 2.0  # waited for the grace period before failing it
    trials = study.trials
    assert trials[dead.number].state == TrialState.FAIL
    finished = study.get_trials(states=FINISHED)
    assert len(finished) == 3
    retry = [t for t in finished if t.system_attrs.get("failed_trial") == dead.number]
    assert len(retry) == 1 and retry[0].params["x"] == x_dead


@pytest.mark.filterwarnings("ignore:Heartbeat of storage")
def test_trial_killed_before_its_first_heartbeat_is_failed_and_retried(tmp_path: Path) -> None:
    """A worker killed between ``ask`` and its first heartbeat: RUNNING with no heartbeat."""
    storage = open_storage(f"sqlite:///{tmp_path / 's.db'}", heartbeat_interval=1,
                           grace_period=2)
    study = open_study(storage, study_name="s", directions=["minimize"])
    orphan = study.ask({"x": FloatDistribution(-3.0, 3.0)})  # no heartbeat, ever
    x_orphan = orphan.params["x"]
    t0 = time.monotonic()
    results = []  # in a thread: without the fix the worker waits for the orphan forever
    worker = threading.Thread(target=lambda: results.append(
        run_worker(study, _objective, n_trials=3, poll_interval=0.1)), daemon=True)
    worker.start()
    worker.join(timeout=30.0)
    assert not worker.is_alive(), "the worker still waits for the trial without a heartbeat"
    result = results[0]
    assert time.monotonic() - t0 >= 2.0  # not failed before the grace period
    assert study.trials[orphan.number].state == TrialState.FAIL
    finished = study.get_trials(states=FINISHED)
    assert len(finished) == 3 == result.complete
    assert not study.get_trials(states=(TrialState.RUNNING, TrialState.WAITING))
    retry = [t for t in finished if t.system_attrs.get("failed_trial") == orphan.number]
    assert len(retry) == 1 and retry[0].params["x"] == x_orphan


def test_nan_and_errors_fail_and_stop_after_max_failures(tmp_path: Path) -> None:
    storage = open_storage(f"sqlite:///{tmp_path / 's.db'}", heartbeat_interval=1)
    study = open_study(storage, study_name="s", directions=["minimize"])
    with pytest.raises(RuntimeError, match="max_failures = 2"):
        run_worker(study, lambda t: float("nan"), n_trials=5, max_failures=2)
    assert [t.state for t in study.trials] == [TrialState.FAIL] * 3


def test_pruned_trials_count(tmp_path: Path) -> None:
    storage = open_storage(f"sqlite:///{tmp_path / 's.db'}", heartbeat_interval=1)
    study = open_study(storage, study_name="s", directions=["minimize"],
                       pruner=optuna.pruners.ThresholdPruner(upper=1.0))

    def objective(trial: optuna.Trial) -> float:
        x = trial.suggest_float("x", -3.0, 3.0)
        trial.report(abs(x), step=0)
        if trial.should_prune():
            raise optuna.TrialPruned()
        return abs(x)

    run_worker(study, objective, n_trials=6)
    finished = study.get_trials(states=FINISHED)
    assert len(finished) == 6
    assert all((t.state == TrialState.PRUNED) == (abs(t.params["x"]) > 1.0) for t in finished)


def test_search_space_syntax() -> None:
    space = SearchSpace.parse({"a": "interval(0.1, 2.0)", "b": "tag(log, interval(1e-4, 1e-1))",
                               "c": "range(2, 11, 3)", "d": "choice(x, 2, true)",
                               "e": "tag(log, int(interval(1, 64)))", "f": 3},
                              ["g=shuffle(range(0, 3))", "h=7"])
    d = space.distributions
    assert d["a"] == FloatDistribution(0.1, 2.0)
    assert d["b"] == FloatDistribution(1e-4, 1e-1, log=True)
    assert d["c"] == IntDistribution(2, 8, step=3)  # stop excluded, as Python's range
    assert d["d"] == CategoricalDistribution(["x", 2, True])
    assert d["e"] == IntDistribution(1, 64, log=True)  # interval() is float unless int(...)
    assert set(d["g"].choices) == {0, 1, 2}
    assert space.fixed == ("f=3", "h=7")
    assert space.overrides({"a": 0.5, "b": 1e-3, "c": 5, "d": True, "e": 2, "g": 1}) == [
        "f=3", "h=7", "a=0.5", "b=0.001", "c=5", "d=true", "e=2", "g=1"]


@pytest.mark.parametrize(("params", "needle"), [
    ({"lr": "glob(*)"}, "lr: unsupported distribution"),
    ({"lr": "tag(log, range(1, 5))"}, "lr: tags ['log'] are not supported on range"),
    ({"lr": "tag(log, interval(0.0, 1.0))"}, "needs a > 0"),
    ({"lr": "interval(2.0, 1.0)"}, "start < end"),
    ({"lr": "tag(grid, interval(0.0, 1.0))"}, "unsupported tag(s) ['grid']"),
])
def test_search_space_rejects(params: dict, needle: str) -> None:
    with pytest.raises(ValueError) as err:
        SearchSpace.parse(params)
    assert needle in str(err.value)


def test_contains() -> None:
    space = SearchSpace.parse({"a": "range(40, 161, 20)", "b": "interval(0.1, 0.4)",
                               "c": "choice(true, false)", "d": "choice(16, 32)"})
    assert space.contains("a", 100) and not space.contains("a", 110)
    assert not space.contains("a", 180) and not space.contains("a", 100.5)
    assert space.contains("b", 0.3) and not space.contains("b", 0.5)
    assert space.contains("c", True) and not space.contains("c", 1)
    assert space.contains("d", 32) and not space.contains("d", 64)
