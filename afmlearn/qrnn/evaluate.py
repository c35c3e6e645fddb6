"""Held-out metrics of an :class:`~afmlearn.qrnn.module.OrbitModule` (design.md section 4).

`evaluate(module, dataloader)` runs the module over a data loader of the data module (batches
as documented in :mod:`afmlearn.qrnn.data`) and returns

``nrmse_period_k`` (k = 1 .. horizon)
    Mean over windows of NRMSE(predicted period k, true period k), with
    NRMSE(a, b) = RMS(a - b) / (max(b) - min(b)) per window and period.
``vpt_periods``
    Valid prediction time: mean over windows of the number of periods before the NRMSE first
    exceeds ``vpt_threshold`` (0.1); a window that never exceeds it counts ``horizon`` (so the
    value is a lower bound when it equals ``horizon``).
``persistence_nrmse_period_k``, ``persistence_vpt_periods``
    The same for the trivial forecast "the input period repeats", a floor any model must beat.
``coupling_auc``, ``coupling_accuracy``
    ROC AUC and accuracy (at ``threshold``) of the per-trace coupling score (mean of the window
    scores of one sweep point) against the ``coupled`` label.
``window_coupling_auc``
    The same AUC per window.
``sweet_iou``
    Mean over sweep directions of the IoU between the predicted sweet-spot interval (from the
    per-point sweet scores) and the labelled one (longest run of labelled points); both empty
    counts 1. ``sweet_iou_labelled`` averages only directions with a labelled sweet spot.
    Set-point series (one drive frequency) have no interval and are left out.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from afmlearn.qrnn.coupling import (
    directions,
    interval_iou,
    roc_auc,
    sweet_spot_interval,
    trace_scores,
)

__all__ = ["evaluate", "collect", "nrmse_per_period", "trace_table",
           "valid_prediction_time"]


def nrmse_per_period(pred: NDArray[np.float64], true: NDArray[np.float64], *, horizon: int
                     ) -> NDArray[np.float64]:
    """NRMSE of each predicted period of each window.

    Parameters
    ----------
    pred, true : ndarray, shape (n_windows, horizon * P)
        Predicted and true deflection (any common unit).
    horizon : int
        Number of periods in the last axis.

    Returns
    -------
    ndarray, shape (n_windows, horizon)
        RMS(pred - true) / (max(true) - min(true)) per window and period (inf for a flat period).
    """
    n = pred.shape[0]
    p = pred.reshape(n, horizon, -1)
    t = true.reshape(n, horizon, -1)
    rms = np.sqrt(np.mean((p - t) ** 2, axis=-1))
    span = t.max(axis=-1) - t.min(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(span > 0, rms / span, np.inf)


def valid_prediction_time(nrmse: NDArray[np.float64], *, threshold: float = 0.1
                          ) -> NDArray[np.float64]:
    """Periods before the NRMSE first exceeds ``threshold``, per window (``horizon`` if never).

    Parameters
    ----------
    nrmse : ndarray, shape (n_windows, horizon)
    """
    above = nrmse > threshold
    first = np.where(above.any(axis=1), above.argmax(axis=1), nrmse.shape[1])
    return first.astype(float)


def collect(module: Any, dataloader: Iterable[dict[str, torch.Tensor]]) -> dict[str, np.ndarray]:
    """Predictions and labels of every window of ``dataloader`` as numpy arrays."""
    keys = ("y", "coupling", "coupled", "sweet", "omega", "sweep_id", "point", "steady")
    out: dict[str, list[np.ndarray]] = {k: [] for k in
                                        ("pred", "coupled_score", "sweet_score", "x0", *keys)}
    for batch in dataloader:
        if "steady" not in batch:
            batch = {**batch, "steady": torch.zeros_like(batch["omega"])}
        r = module.predict_windows(batch["x"])
        out["pred"].append(r["y"].numpy())
        out["coupled_score"].append(r["coupled"].numpy())
        out["sweet_score"].append(r["sweet"].numpy())
        out["x0"].append(batch["x"][:, :, module.deflection_channel].numpy())
        for k in keys:
            out[k].append(batch[k].numpy())
    return {k: np.concatenate(v) for k, v in out.items()}


def trace_table(d: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-trace (per sweep point / set-point) raw scores and labels from `collect` output.

    Returns
    -------
    dict
        ``raw_score`` (mean window coupling score), ``coupled`` (bool), ``coupling`` (the
        label's share of the motion in modes >= 2), ``steady`` (bool: a set-point, not a sweep
        point), ``sweet_score``,
        ``sweet`` (bool), ``omega``, ``sweep_id``, ``point`` -- shape (n_traces,) each.
    """
    key = d["sweep_id"].astype(np.int64) * 1_000_003 + d["point"].astype(np.int64)
    _, score = trace_scores(d["coupled_score"], key)
    _, label = trace_scores(d["coupled"].astype(float), key)
    _, sweet_score = trace_scores(d["sweet_score"], key)
    _, sweet_label = trace_scores(d["sweet"].astype(float), key)
    first = np.unique(key, return_index=True)[1]
    return {"raw_score": score, "coupled": label > 0.5, "sweet_score": sweet_score,
            "coupling": d["coupling"][first].astype(float),
            "steady": d["steady"][first] > 0.5,
            "sweet": sweet_label > 0.5, "omega": d["omega"][first].astype(float),
            "sweep_id": d["sweep_id"][first], "point": d["point"][first]}


def evaluate(module: Any, dataloader: Iterable[dict[str, torch.Tensor]], *,
             threshold: float = 0.5, vpt_threshold: float = 0.1) -> dict[str, float]:
    """Held-out metrics (see the module docstring) of ``module`` on ``dataloader``."""
    d = collect(module, dataloader)
    horizon = int(module.horizon)
    metrics: dict[str, float] = {}
    true = d["y"].astype(float)
    for name, pred in (("", d["pred"].astype(float)),
                       ("persistence_", np.tile(d["x0"].astype(float), (1, horizon)))):
        e = nrmse_per_period(pred, true, horizon=horizon)
        for k in range(horizon):
            metrics[f"{name}nrmse_period_{k + 1}"] = float(np.mean(e[:, k]))
        metrics[f"{name}vpt_periods"] = float(np.mean(valid_prediction_time(
            e, threshold=vpt_threshold)))
    metrics["window_coupling_auc"] = roc_auc(d["coupled"] > 0.5, d["coupled_score"])
    # per trace = per (sweep, point)
    t = trace_table(d)
    score, coupled = t["raw_score"], t["coupled"]
    sweet_score = t["sweet_score"]
    key = d["sweep_id"].astype(np.int64) * 1_000_003 + d["point"].astype(np.int64)
    _, sweet_label = trace_scores(d["sweet"].astype(float), key)  # the share, as labelled
    omega, sweep, point = t["omega"], t["sweep_id"], t["point"]
    metrics["coupling_auc"] = roc_auc(coupled, score)
    metrics["coupling_accuracy"] = float(np.mean((score >= threshold) == coupled))
    metrics["n_traces"] = float(score.size)
    metrics["n_windows"] = float(key.size)
    ious, ious_labelled = [], []
    for s in np.unique(sweep):
        sel = np.flatnonzero(sweep == s)
        sel = sel[np.argsort(point[sel], kind="stable")]
        if np.ptp(omega[sel]) == 0.0:      # a set-point series: no frequency interval
            continue
        for part in directions(omega[sel]):
            idx = sel[part]
            lab = sweet_spot_interval(omega[idx], sweet_label[idx])
            pred = sweet_spot_interval(omega[idx], sweet_score[idx], threshold=threshold)
            iou = interval_iou(omega[idx], pred, lab)
            ious.append(iou)
            if lab is not None:
                ious_labelled.append(iou)
    metrics["sweet_iou"] = float(np.mean(ious)) if ious else float("nan")
    metrics["sweet_iou_labelled"] = (float(np.mean(ious_labelled)) if ious_labelled
                                     else float("nan"))
    metrics["n_sweep_directions"] = float(len(ious))
    return metrics
