"""Heartbeat of a running trial: a daemon thread stamps the storage every interval."""

from __future__ import annotations

import logging
import threading
from types import TracebackType
from typing import final

from optuna.storages import RDBStorage

__all__ = ["Heartbeat"]

log = logging.getLogger(__name__)


@final
class Heartbeat:
    """Context manager: record a heartbeat of ``trial_id`` now and every ``interval`` seconds.

    The first stamp is written before ``__enter__`` returns, so a trial is never running
    without one (a trial without any heartbeat could never be recognised as dead).

    Parameters
    ----------
    storage : RDBStorage
        The study's storage (heartbeats enabled).
    trial_id : int
        Storage id of the running trial (``trial._trial_id``).
    interval : float
        Seconds between stamps, > 0.
    """

    def __init__(self, storage: RDBStorage, trial_id: int, *, interval: float) -> None:
        if not interval > 0:
            raise ValueError(f"interval must be > 0 s, got {interval}")
        self.storage = storage
        self.trial_id = trial_id
        self.interval = float(interval)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> Heartbeat:
        self.storage.record_heartbeat(self.trial_id)
        self._thread = threading.Thread(target=self._run, name=f"heartbeat-{self.trial_id}",
                                        daemon=True)
        self._thread.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            try:
                self.storage.record_heartbeat(self.trial_id)
            except Exception as err:  # a flaky database must not kill the trial
                log.warning("heartbeat of trial id %d failed: %s", self.trial_id, err)
