"""Train an :class:`~afmlearn.qrnn.module.OrbitModule` from a composed Hydra config.

:func:`train` is the one function behind ``scripts/train_qrnn.py`` and the tests
(lightning-hydra-template style): everything is built with ``hydra.utils.instantiate`` from the
``_target_`` nodes of ``conf/train_qrnn.yaml`` and its groups (data, model, trainer, callbacks,
logger, paths); the network is instantiated first and passed into the module.

Run folder ``paths.output_dir``: ``checkpoints/`` (``last.ckpt`` after every finished epoch and
the best one by ``val/loss``), ``csv/``, ``tensorboard/``, ``metrics.json`` (written atomically)
and, with ``export=PATH``, a slim checkpoint (weights and configuration, no optimiser state) as
:func:`export_checkpoint` writes it.

Resuming: with ``ckpt_path=last`` (the default) a run whose folder already holds
``checkpoints/last.ckpt`` continues from it -- the epochs finished before an interruption are kept
(weights, optimiser, scheduler, early-stopping state, epoch and step counters). Reproducible:
``seed_everything(seed, workers=True)`` and ``trainer.deterministic``.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import lightning.pytorch as pl
import numpy as np
import torch
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from lightning.pytorch.callbacks import Callback, ModelCheckpoint
from omegaconf import DictConfig, OmegaConf

from afmlearn.io._atomic import atomic_path
from afmlearn.qrnn.calibration import CouplingCalibration, expected_calibration_error
from afmlearn.qrnn.evaluate import collect, evaluate, trace_table
from afmlearn.qrnn.module import CHECKPOINT_KEY, OrbitModule

__all__ = ["train", "export_checkpoint", "resolve_ckpt_path"]

log = logging.getLogger(__name__)

#: config keys of ``cfg.model`` that are not arguments of the module
_MODEL_META = ("name", "net")


def _instantiate_group(group: DictConfig | None) -> list[Any]:
    """Instantiate every ``_target_`` node of a group (callbacks, loggers), in order."""
    if not group:
        return []
    return [instantiate(node) for node in group.values()
            if isinstance(node, DictConfig) and "_target_" in node]


def resolve_ckpt_path(ckpt_path: str | None, callbacks: list[Callback]) -> str | None:
    """The checkpoint to resume from.

    ``"last"`` means ``last.ckpt`` in the folder of the (first) ModelCheckpoint callback if that
    file exists, else None (start fresh); None stays None; any other value must be an
    existing file.
    """
    if ckpt_path is None:
        return None
    if str(ckpt_path) == "last":
        for cb in callbacks:
            if isinstance(cb, ModelCheckpoint) and cb.dirpath is not None:
                last = Path(cb.dirpath) / f"{ModelCheckpoint.CHECKPOINT_NAME_LAST}.ckpt"
                if last.is_file():
                    return str(last)
        return None
    path = Path(str(ckpt_path))
    if not path.is_file():
        raise ValueError(f"ckpt_path must be 'last', null or an existing checkpoint file, got "
                         f"{ckpt_path!r}")
    return str(path)


def _input_size(datamodule: pl.LightningDataModule) -> tuple[int, int]:
    """(number of input channels, samples per period) of the data module.

    Read from its ``n_features`` / ``samples_per_period`` attributes when it has them (no data
    is touched before ``trainer.fit``, so under DDP only rank 0 generates the cache), else from
    one training batch.
    """
    n_features = getattr(datamodule, "n_features", None)
    samples_per_period = getattr(datamodule, "samples_per_period", None)
    if n_features and samples_per_period:
        return int(n_features), int(samples_per_period)
    datamodule.prepare_data()
    datamodule.setup("fit")
    batch = next(iter(datamodule.train_dataloader()))
    return int(batch["x"].shape[-1]), int(batch["x"].shape[1])


def _build(key: str, node: Any, **kwargs: Any) -> Any:
    """``instantiate(node, **kwargs)``; a bad setting's ValueError, which Hydra wraps in an
    InstantiationException, is raised again as a ValueError naming ``key`` (one line at the
    entry point). Other errors pass unchanged."""
    try:
        return instantiate(node, **kwargs)
    except InstantiationException as err:
        if isinstance(err.__cause__, ValueError):
            raise ValueError(f"{key}: {err.__cause__}") from err
        raise


def _atomic_write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def export_checkpoint(module: OrbitModule, path: str | os.PathLike[str], *,
                      metrics: dict[str, float] | None = None,
                      calibration: CouplingCalibration
                      | dict[str, CouplingCalibration] | None = None) -> Path:
    """Write a slim checkpoint: ``state_dict`` (float32) + afmlearn metadata, no optimiser.

    The file loads with ``torch.load(..., weights_only=True)`` and with
    :func:`afmlearn.qrnn.infer.load_module`. ``calibration`` (the coupling calibration and
    flag threshold, or a dict of them by record kind: ``"all"``, ``"steady"``, ``"sweep"``) is
    stored as plain types under the metadata keys ``calibration`` (all) and
    ``calibration_by_kind``. Written atomically; returns the path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    checkpoint: dict[str, Any] = {
        "state_dict": {k: v.detach().cpu().float() if v.is_floating_point() else v.cpu()
                       for k, v in module.state_dict().items()},
    }
    module.on_save_checkpoint(checkpoint)
    checkpoint[CHECKPOINT_KEY]["metrics"] = dict(metrics or {})
    if isinstance(calibration, CouplingCalibration):
        calibration = {"all": calibration}
    if calibration:
        checkpoint[CHECKPOINT_KEY]["calibration"] = calibration["all"].to_dict()
        checkpoint[CHECKPOINT_KEY]["calibration_by_kind"] = {
            k: c.to_dict() for k, c in calibration.items() if k != "all"}
    with atomic_path(path) as tmp:
        torch.save(checkpoint, tmp)
    return path


def calibrate(module: OrbitModule, datamodule: Any, cfg: Any
              ) -> tuple[dict[str, CouplingCalibration], dict[str, float]]:
    """Fit the coupling calibration on the validation cantilevers (never trained on) and
    measure it on the test cantilevers.

    One calibration (and threshold) for all traces (``"all"``) and, where the validation set
    holds both classes of them, one per record kind: ``"steady"`` (set-points, single steady
    records) and ``"sweep"`` (sweep points); inference uses the kind's own when present, so the
    stated false-flag rate holds per kind.

    Parameters
    ----------
    module : OrbitModule
        The trained module (best weights).
    datamodule : SweepDataModule
    cfg : mapping
        ``calibrator`` (a config node instantiating an
        :class:`~afmlearn.qrnn.calibration.AbstractCalibrator`) and ``false_flag_rate``.

    Returns
    -------
    calibrations : dict of CouplingCalibration
        ``"all"`` and, when fitted, ``"steady"`` and ``"sweep"``.
    metrics : dict
        ``calibration/threshold[_kind]``, ``calibration/false_flag_rate`` (stated),
        ``calibration/val_*`` (on the calibration set) and ``heldout/calibrated_recall``,
        ``heldout/calibrated_false_flags``, ``heldout/calibrated_ece`` (test cantilevers, each
        trace with the calibration of its kind).
    """
    val = trace_table(collect(module, datamodule.val_dataloader()))
    test = trace_table(collect(module, datamodule.test_dataloader()))
    rate = float(cfg.false_flag_rate)
    cals: dict[str, CouplingCalibration] = {}
    for kind, sel in (("all", np.ones(val["steady"].shape, bool)), ("steady", val["steady"]),
                      ("sweep", ~val["steady"])):
        y = val["coupled"][sel]
        if kind != "all" and (y.sum() < 3 or (~y).sum() < 20):
            continue       # too few traces of a class for a calibration of its own
        cals[kind] = CouplingCalibration.fit(val["raw_score"][sel], y,
                                             calibrator=instantiate(cfg.calibrator),
                                             false_flag_rate=rate,
                                             source={"split": "val (held-out cantilevers)",
                                                     "kind": kind})
    p = np.empty(test["raw_score"].shape)
    flag = np.empty(p.shape, bool)
    for steady in (True, False):
        sel = test["steady"] == steady
        cal = cals.get("steady" if steady else "sweep", cals["all"])
        p[sel] = cal.probability(test["raw_score"][sel]) if sel.any() else p[sel]
        flag[sel] = p[sel] >= cal.threshold
    y = test["coupled"]
    out = {"calibration/false_flag_rate": rate,
           **{"calibration/threshold" + ("" if k == "all" else f"_{k}"): c.threshold
              for k, c in cals.items()},
           **{f"calibration/val_{k}": float(v) for k, v in cals["all"].source.items()
              if isinstance(v, int | float)},
           "heldout/calibrated_recall": float(np.mean(flag[y])) if y.any() else float("nan"),
           "heldout/calibrated_false_flags": float(np.mean(flag[~y])),
           "heldout/calibrated_ece": expected_calibration_error(p, y)}
    return cals, out


def _floats(metrics: dict[str, Any]) -> dict[str, float]:
    out = {}
    for k, v in metrics.items():
        if isinstance(v, torch.Tensor) and v.numel() == 1:
            out[k] = float(v)
        elif isinstance(v, int | float):
            out[k] = float(v)
    return out


def train(cfg: DictConfig, *, extra_callbacks: Sequence[Callback] = ()
          ) -> tuple[dict[str, float], dict[str, Any]]:
    """Fit (and test) the configured model; see the module docstring.

    Parameters
    ----------
    cfg : DictConfig
        ``conf/train_qrnn.yaml`` composed with its groups and overrides.
    extra_callbacks : sequence of Callback
        Appended to the configured callbacks (notebooks, tests).

    Returns
    -------
    metrics : dict
        Last logged training / validation values, ``test/...`` losses of the best checkpoint and
        ``heldout/...`` metrics of :func:`afmlearn.qrnn.evaluate.evaluate` on the test split.
    objects : dict
        ``cfg``, ``datamodule``, ``model``, ``trainer``, ``callbacks``, ``loggers``,
        ``ckpt_path`` (resumed from, or None), ``best_model_path``, ``output_dir``.
    """
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    pl.seed_everything(int(cfg.seed), workers=True)
    output_dir = Path(cfg.paths.output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)

    datamodule = _build("data", cfg.data)
    n_features, samples_per_period = _input_size(datamodule)
    net = _build("model.net", cfg.model.net, input_size=n_features)
    module_cfg = OmegaConf.create({k: v for k, v in cfg.model.items() if k not in _MODEL_META})
    model: OrbitModule = _build("model", module_cfg, net=net)
    model.run_config = {
        "config": OmegaConf.to_container(cfg, resolve=True),
        "input_size": n_features,
        "samples_per_period": samples_per_period,
        "horizon": int(model.horizon),
    }

    callbacks = [*_instantiate_group(cfg.get("callbacks")), *extra_callbacks]
    loggers = _instantiate_group(cfg.get("logger"))
    trainer: pl.Trainer = instantiate(cfg.trainer, callbacks=callbacks, logger=loggers or False)
    ckpt_path = resolve_ckpt_path(cfg.get("ckpt_path"), callbacks)
    if ckpt_path is not None:
        log.info("resuming from %s", ckpt_path)

    metrics: dict[str, float] = {}
    if cfg.get("fit", True):
        trainer.fit(model, datamodule=datamodule, ckpt_path=ckpt_path)
        metrics.update(_floats(trainer.callback_metrics))
    metrics["epochs_completed"] = float(trainer.current_epoch)
    metrics["global_step"] = float(trainer.global_step)
    best = ""
    if trainer.checkpoint_callback is not None:
        best = getattr(trainer.checkpoint_callback, "best_model_path", "") or ""
    if cfg.get("test", True):
        test_ckpt = best if best and Path(best).is_file() else None
        if test_ckpt is None and not cfg.get("fit", True) and ckpt_path is not None:
            test_ckpt = ckpt_path
        trainer.test(model, datamodule=datamodule, ckpt_path=test_ckpt, verbose=False)
        metrics.update(_floats(trainer.callback_metrics))
        datamodule.setup("test")
        held = evaluate(model, datamodule.test_dataloader())
        metrics.update({f"heldout/{k}": v for k, v in held.items()})
    calibration = None
    if cfg.get("calibration") and cfg.get("test", True):
        try:
            calibration, cal_metrics = calibrate(model, datamodule, cfg.calibration)
            metrics.update(cal_metrics)
        except ValueError as err:  # e.g. a tiny validation split with one class only
            log.warning("coupling calibration skipped: %s", err)
    if trainer.is_global_zero:
        _atomic_write_text(output_dir / "metrics.json",
                           json.dumps(metrics, indent=2, sort_keys=True) + "\n")
        if cfg.get("export"):
            export_checkpoint(model, cfg.export, metrics=metrics, calibration=calibration)
    objects = {"cfg": cfg, "datamodule": datamodule, "model": model, "trainer": trainer,
               "callbacks": callbacks, "loggers": loggers, "ckpt_path": ckpt_path,
               "best_model_path": best, "output_dir": output_dir}
    return metrics, objects
