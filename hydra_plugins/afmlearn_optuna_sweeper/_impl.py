"""Implementation of the sweeper: check the search space, open the study, run workers, report.

One sweep:

1. parse ``params`` and the command line into a :class:`afmlearn.tune.SearchSpace` and compose
   the job config once with an example value of every parameter -- an unknown path, an
   unsupported distribution or a bad setting stops here (``error: ...``, exit status 2) before
   any trial runs;
2. open (or create) the study on ``storage`` (default SQLite under ``outputs/optuna``) with
   heartbeats and retry of dead trials;
3. start ``n_jobs - 1`` copies of the same command as extra workers (they only run trials) and
   run :func:`afmlearn.tune.run_worker` here; each trial launches the job (once per fold) through
   the configured launcher with the trial published as :func:`afmlearn.tune.current_trial`;
4. write the results (:func:`afmlearn.tune.write_results`, figures) and print a summary table.
"""

from __future__ import annotations

import logging
import math
import os
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

import optuna
from hydra.core.plugins import Plugins
from hydra.types import HydraContext, TaskFunction
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from afmlearn.tune import (
    SearchSpace,
    default_storage_url,
    format_value,
    open_storage,
    open_study,
    run_worker,
    running,
    summary_table,
    write_results,
)

log = logging.getLogger(__name__)

#: environment variable marking a worker started by another sweep (value: its index)
WORKER_ENV = "AFMLEARN_OPTUNA_WORKER"


def _bad_input(err: Exception) -> None:
    """One line on stderr, exit status 2 (the scripts' convention for bad input)."""
    print(f"error: {err}", file=sys.stderr)
    sys.exit(2)


class OptunaSweeperImpl:
    """See the module docstring; settings as :class:`..config.OptunaSweeperConf`."""

    def __init__(self, *, sampler: Any = None, pruner: Any = None, direction: Any = "minimize",
                 storage: Any = None, study_name: Any = None, n_trials: int = 20,
                 n_jobs: int = 1, max_failures: Any = None, heartbeat_interval: int = 60,
                 grace_period: Any = None, max_retry: int = 3, folds: Any = None,
                 results_dir: str = "outputs/tuned", figures: bool = True,
                 baseline: bool = False, params: Any = None) -> None:
        self.sampler = sampler
        self.pruner = pruner
        self.direction = direction
        self.storage = storage
        self.study_name = study_name
        self.n_trials = n_trials
        self.n_jobs = n_jobs
        self.max_failures = max_failures
        self.heartbeat_interval = heartbeat_interval
        self.grace_period = grace_period
        self.max_retry = max_retry
        self.folds = folds
        self.results_dir = results_dir
        self.figures = figures
        self.baseline = baseline
        self.params = params

    # ------------------------------------------------------------------ hydra interface
    def setup(self, *, hydra_context: HydraContext, task_function: TaskFunction,
              config: DictConfig) -> None:
        self.config = config
        self.hydra_context = hydra_context
        self.launcher = Plugins.instance().instantiate_launcher(
            config=config, hydra_context=hydra_context, task_function=task_function)

    def sweep(self, arguments: list[str]) -> None:
        try:
            space, folds = self._checked(arguments)
            directions = self._directions()
            name = str(self.study_name or self.config.hydra.job.name)
            url = str(self.storage) if self.storage else default_storage_url(name)
            storage = open_storage(url, heartbeat_interval=int(self.heartbeat_interval),
                                   grace_period=self.grace_period,
                                   max_retry=int(self.max_retry))
            sampler_cfg, pruner = self._sampler_cfg(), self._pruner()
            study = open_study(storage, study_name=name, directions=directions,
                               sampler=instantiate(sampler_cfg), pruner=pruner)
        except ValueError as err:
            _bad_input(err)
        index = int(os.environ.get(WORKER_ENV, "0"))
        log.info("study %s on %s: %d trials, worker %d", name, url.split("@")[-1],
                 self.n_trials, index)
        if index == 0 and self.baseline and not study.trials:
            self._enqueue_baseline(study, space)
        children = self._spawn_workers() if index == 0 else []
        seed = sampler_cfg.get("seed")
        factory = None if seed is None else (
            lambda s: instantiate(sampler_cfg, seed=(int(seed) + s) % 2**32))
        try:
            result = run_worker(study, self._objective(space, folds), n_trials=int(self.n_trials),
                                poll_interval=min(2.0, float(self.heartbeat_interval)),
                                max_failures=self.max_failures, sampler_factory=factory,
                                worker_index=index)
        except BaseException:
            for child in children:  # their running trials go stale and are retried on resume
                child.terminate()
            raise
        finally:
            for child in children:
                child.wait()
        log.info("worker %d: %d complete, %d pruned, %d failed in %.1f s", index,
                 result.complete, result.pruned, result.failed, result.seconds)
        if index == 0:
            self._report(study, space)

    # ------------------------------------------------------------------ checks
    def _checked(self, arguments: list[str]) -> tuple[SearchSpace, tuple[str, list[Any]] | None]:
        """The search space and the folds, checked against the job config (ValueError)."""
        params = (OmegaConf.to_container(self.params, resolve=False)
                  if isinstance(self.params, DictConfig) else self.params)
        space = SearchSpace.parse(params, arguments)
        if int(self.n_trials) < 0:
            raise ValueError(f"hydra.sweeper.n_trials must be >= 0, got {self.n_trials}")
        if int(self.n_jobs) < 1:
            raise ValueError(f"hydra.sweeper.n_jobs must be >= 1, got {self.n_jobs}")
        folds = None
        if self.folds is not None:
            key, values = self.folds.get("key"), list(self.folds.get("values") or [])
            if not key or not values:
                raise ValueError("hydra.sweeper.folds needs a key and a non-empty list of "
                                 f"values, got {OmegaConf.to_container(self.folds)}")
            folds = (str(key), values)
        example = space.overrides(space.example())
        if folds is not None:
            example.append(f"{folds[0]}={format_value(folds[1][0])}")
        loader = self.hydra_context.config_loader
        try:
            loader.load_sweep_config(self.config, example)
        except Exception:
            for key, text in self._single_overrides(space, folds):
                try:
                    loader.load_sweep_config(self.config, [*space.fixed, text])
                except Exception as err:
                    first = str(err).strip().splitlines()[0] if str(err).strip() else ""
                    raise ValueError(f"hydra.sweeper.params: {key!r} is not a path of the "
                                     f"config or cannot take {text!r} ({first})") from None
            raise
        return space, folds

    def _enqueue_baseline(self, study: optuna.Study, space: SearchSpace) -> None:
        """Queue the config's own values as the first trial (the "before" of the study)."""
        cfg = self.hydra_context.config_loader.load_sweep_config(self.config, list(space.fixed))
        params = {}
        for key in space.distributions:
            path = key.lstrip("+~")
            value = (OmegaConf.select(cfg, f"hydra.runtime.choices.{path}")
                     if self.hydra_context.config_loader.get_group_options(path.replace(".", "/"))
                     else OmegaConf.select(cfg, path))
            if not space.contains(key, value):
                log.warning("baseline: %s = %r is outside the search space; not enqueued",
                            key, value)
                return
            params[key] = value
        study.enqueue_trial(params, user_attrs={"baseline": True})
        log.info("baseline trial queued: %s", params)

    @staticmethod
    def _single_overrides(space: SearchSpace, folds: tuple[str, list[Any]] | None
                          ) -> list[tuple[str, str]]:
        out = [(k, f"{k}={format_value(v)}") for k, v in space.example().items()]
        if folds is not None:
            out.append((folds[0], f"{folds[0]}={format_value(folds[1][0])}"))
        return out

    def _directions(self) -> list[str]:
        raw = self.direction
        items = list(raw) if isinstance(raw, Sequence) and not isinstance(raw, str) else [raw]
        out = []
        for d in items:
            text = str(getattr(d, "name", d)).lower()
            if text not in ("minimize", "maximize"):
                raise ValueError(f"hydra.sweeper.direction must be minimize or maximize, got "
                                 f"{d!r}")
            out.append(text)
        return out

    def _sampler_cfg(self) -> DictConfig:
        # Hydra hands the sweeper an instantiated sampler: re-read its node (re-seeded per trial)
        node = OmegaConf.select(self.config, "hydra.sweeper.sampler")
        cfg = OmegaConf.create({"_target_": "optuna.samplers.TPESampler", "seed": None}
                               if node is None else OmegaConf.to_container(node))
        if "_target_" not in cfg:
            raise ValueError("hydra.sweeper.sampler needs a _target_ (e.g. "
                             "optuna.samplers.TPESampler)")
        try:
            sampler = instantiate(cfg)
        except Exception as err:
            raise ValueError(f"hydra.sweeper.sampler: cannot build {cfg._target_}: {err}"
                             ) from None
        if not isinstance(sampler, optuna.samplers.BaseSampler):
            raise ValueError(f"hydra.sweeper.sampler: {cfg._target_} is not an Optuna sampler")
        if "seed" not in cfg:
            OmegaConf.set_struct(cfg, False)
            cfg.seed = None
        return cfg

    def _pruner(self) -> optuna.pruners.BasePruner:
        if self.pruner is None:  # `hydra.sweeper.pruner=null`: no pruning
            return optuna.pruners.NopPruner()
        pruner = self.pruner  # instantiated by Hydra
        if not isinstance(pruner, optuna.pruners.BasePruner):
            raise ValueError(f"hydra.sweeper.pruner: {type(pruner).__name__} is not an Optuna "
                             "pruner")
        return pruner

    # ------------------------------------------------------------------ trials
    def _objective(self, space: SearchSpace, folds: tuple[str, list[Any]] | None) -> Any:
        n_folds = 1 if folds is None else len(folds[1])

        def objective(trial: optuna.Trial) -> float | list[float]:
            params = space.suggest(trial)
            base = space.overrides(params)
            if folds is None:
                return self._launch(trial, base, trial.number)
            values = []
            for k, value in enumerate(folds[1]):
                out = self._launch(trial, [*base, f"{folds[0]}={format_value(value)}"],
                                   trial.number * n_folds + k)
                values.append(float(out))  # type: ignore[arg-type]
                trial.set_user_attr("fold_values", values)
                mean = math.fsum(values) / len(values)
                if math.isnan(mean):
                    return mean
                trial.report(mean, step=k)
                if trial.should_prune():
                    raise optuna.TrialPruned(f"pruned after fold {k} (mean {mean:.6g})")
            return math.fsum(values) / len(values)

        return objective

    def _launch(self, trial: optuna.Trial, overrides: list[str], job_idx: int
                ) -> float | list[float]:
        log.info("trial %d: %s", trial.number, " ".join(overrides))
        with running(trial):
            try:
                ret = self.launcher.launch([tuple(overrides)], initial_job_idx=job_idx)[0]
            except SystemExit as err:  # a task's exit on bad input fails the trial only
                raise RuntimeError(f"the job exited with status {err.code}") from None
            value = ret.return_value  # re-raises the job's exception (TrialPruned included)
        if isinstance(value, Sequence) and not isinstance(value, str):
            return [float(v) for v in value]
        try:
            return float(value)
        except (TypeError, ValueError):
            raise ValueError(f"the task function must return a number, got {value!r}") from None

    # ------------------------------------------------------------------ workers, results
    def _spawn_workers(self) -> list[subprocess.Popen[bytes]]:
        """``n_jobs - 1`` copies of this command, each a worker of the same study."""
        out = []
        for i in range(1, int(self.n_jobs)):
            env = {**os.environ, WORKER_ENV: str(i)}
            out.append(subprocess.Popen([sys.executable, *sys.argv], env=env))
            log.info("started worker %d (pid %d)", i, out[-1].pid)
        return out

    def _report(self, study: optuna.Study, space: SearchSpace) -> None:
        loader = self.hydra_context.config_loader
        groups = [k for k in space.distributions
                  if loader.get_group_options(k.lstrip("+~").replace(".", "/"))]
        files = write_results(study, results_dir=self.results_dir, groups=groups)
        if self.figures:
            from afmlearn.plots.tune import write_figures

            files.update(write_figures(study, os.path.join(self.results_dir, study.study_name,
                                                           "figures")))
        print(summary_table(study))
        for key, path in files.items():
            print(f"{key:<12} {path}")
