"""Pruning callback for Lightning training under a study (QRNN trials, per epoch)."""

from __future__ import annotations

import logging

from lightning.pytorch.callbacks import Callback

from .context import current_trial

__all__ = ["lightning_pruning"]

log = logging.getLogger(__name__)


def lightning_pruning(monitor: str = "val/loss") -> Callback:
    """optuna-integration's ``PyTorchLightningPruningCallback`` on the current trial.

    Reports ``monitor`` after every validation epoch and raises :class:`optuna.TrialPruned`
    when the study's pruner says so. Outside a study (no :func:`current_trial`) it returns a
    callback that does nothing, so a config that lists it also trains without the sweeper.

    Parameters
    ----------
    monitor : str
        Logged metric to report (``val/loss``).
    """
    trial = current_trial()
    if trial is None:
        log.info("no Optuna trial running: the pruning callback is off")
        return Callback()
    from optuna_integration import PyTorchLightningPruningCallback

    return PyTorchLightningPruningCallback(trial, monitor=monitor)
