"""Study storage: an SQLAlchemy database with heartbeats, so interrupted trials are retried.

``storage=null`` means ``sqlite:///outputs/optuna/<study_name>.db`` (relative to the working
directory); any SQLAlchemy URL works (``postgresql://user@host:5432/db`` for several machines).
Every worker records a heartbeat of its running trial every ``heartbeat_interval`` seconds; a
trial whose heartbeat is older than ``grace_period`` (its process died) is marked ``FAIL`` by
the next worker that looks, and a copy with the same parameters is queued
(:class:`optuna.storages.RetryHeartbeatStaleTrialCallback`), at most ``max_retry`` times.
"""

from __future__ import annotations

import logging
import random
import time
import warnings
from pathlib import Path

import optuna
from optuna.storages import RDBStorage, RetryHeartbeatStaleTrialCallback

__all__ = ["default_storage_url", "open_storage", "open_study"]

log = logging.getLogger(__name__)


def default_storage_url(study_name: str, *, root: str | Path = "outputs/optuna") -> str:
    """``sqlite:///<abs root>/<study_name>.db``; creates the folder."""
    if not study_name or any(c in study_name for c in "/\\"):
        raise ValueError(f"study_name must be a non-empty name without slashes, got "
                         f"{study_name!r}")
    folder = Path(root).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{folder / f'{study_name}.db'}"


def open_storage(url: str, *, heartbeat_interval: int = 60, grace_period: int | None = None,
                 max_retry: int = 3) -> RDBStorage:
    """An :class:`optuna.storages.RDBStorage` with heartbeats and retry of stale trials.

    Parameters
    ----------
    url : str
        SQLAlchemy URL.
    heartbeat_interval : int
        Seconds between heartbeats of a running trial, >= 1.
    grace_period : int or None
        Seconds without heartbeat after which a running trial counts as dead
        (None: ``2 * heartbeat_interval``), > ``heartbeat_interval``.
    max_retry : int
        Retries of one dead trial, >= 0.

    Raises
    ------
    ValueError
        Bad settings, or a URL SQLAlchemy cannot use (naming it).
    """
    if int(heartbeat_interval) < 1:
        raise ValueError(f"hydra.sweeper.heartbeat_interval must be >= 1 s, got "
                         f"{heartbeat_interval}")
    grace = 2 * int(heartbeat_interval) if grace_period is None else int(grace_period)
    if grace <= int(heartbeat_interval):
        raise ValueError(f"hydra.sweeper.grace_period must exceed heartbeat_interval "
                         f"({heartbeat_interval} s), got {grace}")
    if int(max_retry) < 0:
        raise ValueError(f"hydra.sweeper.max_retry must be >= 0, got {max_retry}")
    engine_kwargs = {"connect_args": {"timeout": 60}} if url.startswith("sqlite") else {}
    last: Exception | None = None
    for attempt in range(5):  # workers started together may race on creating the tables
        try:
            with warnings.catch_warnings():  # heartbeats are "experimental" since Optuna 2.9
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                return RDBStorage(url, engine_kwargs=engine_kwargs,
                                  heartbeat_interval=int(heartbeat_interval),
                                  grace_period=grace,
                                  heartbeat_stale_trial_callback=RetryHeartbeatStaleTrialCallback(
                                      max_retry=int(max_retry)))
        except (ImportError, ValueError) as err:
            raise ValueError(f"hydra.sweeper.storage: cannot open {_redacted(url)!r}: {err}"
                             ) from None
        except Exception as err:  # sqlalchemy.exc.*: a concurrent CREATE TABLE, a busy server
            last = err
            time.sleep(0.5 + random.random() * (attempt + 1))
    raise ValueError(f"hydra.sweeper.storage: cannot open {_redacted(url)!r}: {last}")


def open_study(storage: RDBStorage, *, study_name: str, directions: list[str],
               sampler: optuna.samplers.BaseSampler | None = None,
               pruner: optuna.pruners.BasePruner | None = None) -> optuna.Study:
    """Create the study or load it if it exists (the same command resumes it)."""
    for attempt in range(5):
        try:
            return optuna.create_study(storage=storage, study_name=study_name,
                                       directions=directions, sampler=sampler, pruner=pruner,
                                       load_if_exists=True)
        except optuna.exceptions.DuplicatedStudyError:  # created by a concurrent worker
            time.sleep(0.2 * (attempt + 1))
    return optuna.load_study(storage=storage, study_name=study_name, sampler=sampler,
                             pruner=pruner)


def _redacted(url: str) -> str:
    """The URL without its password."""
    head, sep, tail = url.partition("@")
    if not sep or ":" not in head.split("//", 1)[-1]:
        return url
    scheme, _, cred = head.partition("//")
    return f"{scheme}//{cred.split(':', 1)[0]}:***@{tail}"
