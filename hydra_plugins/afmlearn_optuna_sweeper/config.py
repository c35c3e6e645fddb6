"""Structured config of the sweeper, registered as ``hydra/sweeper: optuna``.

The keys are those of hydra-optuna-sweeper (``n_trials``, ``n_jobs``, ``direction``,
``storage``, ``study_name``, ``sampler``, ``params``), so a lightning-hydra-template
``hparams_search`` config switches by changing its ``_target_`` line (or deleting it); the
rest are additions (see docs/tuning.md).
"""

from dataclasses import dataclass
from typing import Any

from hydra.core.config_store import ConfigStore

TARGET = "hydra_plugins.afmlearn_optuna_sweeper.optuna_sweeper.OptunaSweeper"


@dataclass
class OptunaSweeperConf:
    """Settings of :class:`~hydra_plugins.afmlearn_optuna_sweeper.optuna_sweeper.OptunaSweeper`.

    Attributes
    ----------
    sampler : node or None
        ``_target_`` node of an Optuna sampler (None: TPE); a ``seed`` makes the study
        reproducible (each trial's sampler is seeded from it, the worker and the trial count).
    pruner : node or None
        ``_target_`` node of an Optuna pruner (None: no pruning, Optuna's ``NopPruner``).
    direction : str or list of str
        ``minimize`` / ``maximize`` (a list: several objectives, no pruning).
    storage : str or None
        SQLAlchemy URL; None: ``sqlite:///outputs/optuna/<study_name>.db``.
    study_name : str or None
        None: the job name (the script's name).
    n_trials : int
        Complete-or-pruned trials the study must reach (over all workers and re-runs).
    n_jobs : int
        Worker processes on this machine (this one and ``n_jobs - 1`` copies of the command).
    max_failures : int or None
        Failed trials one worker tolerates before stopping (None: ``n_trials``).
    heartbeat_interval, grace_period : int, int or None
        Seconds between heartbeats of a running trial; seconds after which a silent trial is
        dead, marked failed and retried (None: twice the interval).
    max_retry : int
        Retries of one dead trial.
    folds : node or None
        ``{key: seed, values: [0, 1, 2]}``: run the job once per value (override
        ``key=value``); the trial's value is the mean, reported after each fold for pruning.
    results_dir : str
        Where best.yaml, summary.json, figures/ and experiment/<study_name>.yaml go.
    figures : bool
        Draw history, importances and parallel coordinates at the end.
    baseline : bool
        When the study is new, queue the config's own values of the searched parameters as
        its first trial (the "before" of the study, measured under the same conditions).
    params : dict or None
        Config path -> sweep (``interval(a, b)``, ``tag(log, interval(a, b))``,
        ``range(a, b[, s])``, ``choice(...)``) or fixed value.
    """

    _target_: str = TARGET
    sampler: Any = None
    pruner: Any = None
    direction: Any = "minimize"
    storage: Any = None
    study_name: Any = None
    n_trials: int = 20
    n_jobs: int = 1
    max_failures: Any = None
    heartbeat_interval: int = 60
    grace_period: Any = None
    max_retry: int = 3
    folds: Any = None
    results_dir: str = "outputs/tuned"
    figures: bool = True
    baseline: bool = False
    params: Any = None


ConfigStore.instance().store(group="hydra/sweeper", name="optuna", node=OptunaSweeperConf,
                             provider="afmlearn")
ConfigStore.instance().store(group="hydra/sweeper", name="afmlearn_optuna",
                             node=OptunaSweeperConf, provider="afmlearn")
