"""The Optuna trial a task function is running under, for intermediate reports and pruning.

The sweeper runs each trial's Hydra job in its own process (the basic launcher) and publishes
the trial here while the job runs; a task reads it with :func:`current_trial` (None outside a
study, so the same task runs unchanged without the sweeper). :func:`report` is the one place a
task reports an intermediate value and is pruned.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import optuna

__all__ = ["current_trial", "running", "report"]

_TRIAL: list[optuna.Trial] = []


def current_trial() -> optuna.Trial | None:
    """The trial of the job running in this process, or None."""
    return _TRIAL[-1] if _TRIAL else None


@contextmanager
def running(trial: optuna.Trial) -> Iterator[optuna.Trial]:
    """Publish ``trial`` as the current one for the duration of the block."""
    _TRIAL.append(trial)
    try:
        yield trial
    finally:
        _TRIAL.pop()


def report(value: float, step: int) -> None:
    """Report an intermediate objective value; raise :class:`optuna.TrialPruned` if pruned.

    Does nothing outside a study.

    Parameters
    ----------
    value : float
        The objective so far (same direction as the final value).
    step : int
        Step index (epoch, fold), >= 0, increasing.
    """
    trial = current_trial()
    if trial is None:
        return
    trial.report(float(value), step=int(step))
    if trial.should_prune():
        raise optuna.TrialPruned(f"trial {trial.number} pruned at step {step}")
