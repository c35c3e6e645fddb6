"""One worker of a study: take trials until the study holds ``n_trials`` finished ones.

Any number of workers (processes on one machine, jobs on many) run :func:`run_worker` on the
same storage. The invariant they keep together: the study ends with exactly ``n_trials`` trials
``COMPLETE`` or ``PRUNED``; a trial whose process died is marked ``FAIL`` (heartbeat) and its
parameters are retried (see :mod:`afmlearn.tune.storage`).

Each round a worker

1. fails stale trials (``optuna.storages.fail_stale_trials``: their retries are queued), and
   also a trial that is ``RUNNING`` without any heartbeat and started more than the grace
   period ago (its process died between ``study.ask()`` and its first heartbeat, which
   Optuna's check never fails),
2. stops if ``n_trials`` trials are finished; waits if the remaining ones are all running
   (they may still die and need a retry),
3. asks for a trial (a queued retry first) and claims a slot: among the running trials, the
   ones with smaller numbers go first, and a trial beyond ``n_trials`` is handed back to the
   queue (state ``WAITING``) -- so two workers asking at once never overshoot,
4. runs the objective under a :class:`~afmlearn.tune.heartbeat.Heartbeat` and tells the result:
   a value (``COMPLETE``), :class:`optuna.TrialPruned` (``PRUNED``), NaN or an exception
   (``FAIL``; more than ``max_failures`` of them in one worker stop it).

A sampler factory gives every trial a sampler seeded from (seed, worker, trials so far), so a
resumed or parallel study draws new points instead of repeating the first ones.
"""

from __future__ import annotations

import copy
import logging
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import final

import optuna
from optuna.storages import RDBStorage, fail_stale_trials
from optuna.storages._rdb import models
from optuna.trial import TrialState

from .heartbeat import Heartbeat

__all__ = ["run_worker", "WorkerResult", "TooManyFailuresError", "FINISHED"]

log = logging.getLogger(__name__)

#: states that count towards ``n_trials``
FINISHED = (TrialState.COMPLETE, TrialState.PRUNED)

Objective = Callable[[optuna.Trial], float | Sequence[float]]


class TooManyFailuresError(RuntimeError):
    """A worker saw more failed trials than ``max_failures``."""


@final
@dataclass(frozen=True)
class WorkerResult:
    """What one worker did.

    Attributes
    ----------
    complete, pruned, failed : int
        Trials this worker finished in each state.
    seconds : float
        Wall time of the trials it ran [s].
    """

    complete: int
    pruned: int
    failed: int
    seconds: float


def _counts(study: optuna.Study) -> tuple[int, list[int]]:
    """(finished trials, sorted numbers of running trials)."""
    trials = study.get_trials(deepcopy=False, states=(*FINISHED, TrialState.RUNNING))
    finished = sum(t.state in FINISHED for t in trials)
    return finished, sorted(t.number for t in trials if t.state == TrialState.RUNNING)


def _fail_without_heartbeat(study: optuna.Study) -> list[int]:
    """Fail ``RUNNING`` trials with no heartbeat record that started over the grace period ago.

    Such a trial's process died between ``study.ask()`` and its first heartbeat; Optuna's
    :func:`~optuna.storages.fail_stale_trials` only looks at trials with a heartbeat, so the
    study would wait for it forever. It is failed like a heartbeat-stale trial: the storage's
    stale-trial callback queues its retry. The start time is Optuna's (the asking process's
    local clock), compared with this process's clock. Returns the numbers of the trials failed.
    """
    storage = study._storage  # an RDBStorage, wrapped by Optuna in a cache
    rdb = getattr(storage, "_backend", storage)
    if not isinstance(rdb, RDBStorage) or rdb.heartbeat_interval is None:
        return []
    grace = rdb.grace_period or 2 * rdb.heartbeat_interval
    cutoff = datetime.now() - timedelta(seconds=grace)
    session = rdb.scoped_session()
    try:
        ids = [row[0] for row in session.query(models.TrialModel.trial_id)
               .filter(models.TrialModel.study_id == study._study_id)
               .filter(models.TrialModel.state == TrialState.RUNNING)
               .filter(~models.TrialModel.heartbeats.any()).all()]
        session.commit()
    finally:
        session.close()
    callback = storage.get_heartbeat_stale_trial_callback()
    failed = []
    for trial_id in ids:
        start = storage.get_trial(trial_id).datetime_start  # local time, as Optuna reports it
        if start is None or start >= cutoff:
            continue
        try:
            if not storage.set_trial_state_values(trial_id, state=TrialState.FAIL):
                continue
        except optuna.exceptions.UpdateFinishedTrialError:  # finished or failed elsewhere
            continue
        trial = copy.deepcopy(storage.get_trial(trial_id))
        log.warning("trial %d has been running for over %g s without a heartbeat (its worker "
                    "died before the first one): failed", trial.number, grace)
        failed.append(trial.number)
        if callback is not None:
            callback(study, trial)
    return failed


def _values(value: float | Sequence[float], n_objectives: int) -> list[float]:
    values = [float(value)] if n_objectives == 1 else [float(v) for v in value]  # type: ignore[union-attr]
    if len(values) != n_objectives:
        raise ValueError(f"the task returned {len(values)} values for {n_objectives} objectives")
    return values


def run_worker(study: optuna.Study, objective: Objective, *, n_trials: int,
               poll_interval: float = 2.0, max_failures: int | None = None,
               sampler_factory: Callable[[int], optuna.samplers.BaseSampler] | None = None,
               worker_index: int = 0) -> WorkerResult:
    """Run trials of ``study`` until it holds ``n_trials`` complete-or-pruned trials.

    Parameters
    ----------
    study : optuna.Study
        On an RDB storage with heartbeats (:func:`afmlearn.tune.storage.open_storage`).
    objective : callable
        ``objective(trial) -> float`` (or one float per direction); may raise
        :class:`optuna.TrialPruned`.
    n_trials : int
        Target number of complete-or-pruned trials of the whole study, >= 0.
    poll_interval : float
        Seconds between looks while the last trials run elsewhere, > 0.
    max_failures : int or None
        Failed trials this worker tolerates (None: ``max(n_trials, 1)``).
    sampler_factory : callable or None
        ``seed -> sampler``; called before every trial with
        ``seed = 1_000_003 * worker_index + trials in the study``. None keeps the study's.
    worker_index : int
        Index of this worker among those started together (0 for the first).

    Returns
    -------
    WorkerResult

    Raises
    ------
    TooManyFailuresError
        More than ``max_failures`` trials failed in this worker.
    """
    if int(n_trials) < 0:
        raise ValueError(f"hydra.sweeper.n_trials must be >= 0, got {n_trials}")
    limit = max(int(n_trials), 1) if max_failures is None else int(max_failures)
    storage = study._storage  # the public study has no storage accessor
    interval = float(storage.get_heartbeat_interval() or 60)
    n_objectives = len(study.directions)
    done = {TrialState.COMPLETE: 0, TrialState.PRUNED: 0, TrialState.FAIL: 0}
    seconds = 0.0
    while True:
        with warnings.catch_warnings():  # "experimental" since Optuna 2.9; and we do not use
            warnings.simplefilter("ignore")  # Study.optimize, which the heartbeat warns about
            fail_stale_trials(study)
        _fail_without_heartbeat(study)
        finished, running = _counts(study)
        if finished >= n_trials:
            break
        if finished + len(running) >= n_trials:
            time.sleep(poll_interval)
            continue
        if sampler_factory is not None:
            n_all = len(study.get_trials(deepcopy=False))
            study.sampler = sampler_factory(1_000_003 * worker_index + n_all)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            trial = study.ask()
        storage.record_heartbeat(trial._trial_id)
        finished, running = _counts(study)
        rank = running.index(trial.number) if trial.number in running else len(running)
        if finished + rank >= n_trials:  # another worker holds the last slots: hand it back
            storage.set_trial_state_values(trial._trial_id, state=TrialState.WAITING)
            log.info("trial %d handed back: the last slots are taken", trial.number)
            time.sleep(poll_interval)
            continue
        t0 = time.perf_counter()
        state, values = TrialState.FAIL, None
        with Heartbeat(storage, trial._trial_id, interval=interval):
            try:
                values = _values(objective(trial), n_objectives)
                state = (TrialState.FAIL if any(math.isnan(v) for v in values)
                         else TrialState.COMPLETE)
                if state == TrialState.FAIL:
                    log.warning("trial %d returned NaN: failed", trial.number)
                    values = None
            except optuna.TrialPruned as err:
                state = TrialState.PRUNED
                log.info("trial %d pruned: %s", trial.number, err)
            except Exception as err:
                log.warning("trial %d failed: %s: %s", trial.number, type(err).__name__, err)
            seconds += time.perf_counter() - t0
            trial.set_user_attr("wall_time_s", time.perf_counter() - t0)
            try:
                study.tell(trial, values=values, state=state)
            except optuna.exceptions.UpdateFinishedTrialError:
                log.warning("trial %d was finished by another worker", trial.number)
                continue
        done[state] += 1
        if done[TrialState.FAIL] > limit:
            raise TooManyFailuresError(f"{done[TrialState.FAIL]} trials failed in this worker "
                                       f"(hydra.sweeper.max_failures = {limit})")
    return WorkerResult(complete=done[TrialState.COMPLETE], pruned=done[TrialState.PRUNED],
                        failed=done[TrialState.FAIL], seconds=seconds)
