"""Hyper-parameter tuning with Optuna under Hydra (issue 13).

The Hydra sweeper (``hydra_plugins/afmlearn_optuna_sweeper``, ``hydra/sweeper: optuna``) is
built from the pieces here: the search space in Hydra's sweep syntax (:class:`SearchSpace`),
the storage with heartbeats and retries (:func:`open_storage`, :func:`open_study`), the worker
loop that keeps a study at exactly ``n_trials`` finished trials (:func:`run_worker`), the trial a
task runs under (:func:`current_trial`, :func:`report`), pruning callbacks and the results
(:func:`write_results`, :func:`summary_table`). Method and recipes: docs/tuning.md.
"""

from .context import current_trial, report, running
from .results import experiment_config, summary, summary_table, write_results
from .space import SearchSpace, format_value
from .storage import default_storage_url, open_storage, open_study
from .worker import FINISHED, TooManyFailuresError, WorkerResult, run_worker

__all__ = [
    "FINISHED",
    "SearchSpace",
    "TooManyFailuresError",
    "WorkerResult",
    "current_trial",
    "default_storage_url",
    "experiment_config",
    "format_value",
    "open_storage",
    "open_study",
    "report",
    "run_worker",
    "running",
    "summary",
    "summary_table",
    "write_results",
]
