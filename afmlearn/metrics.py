"""Accuracy metrics, defined once for the whole project (``design.md`` section 4).

- ``NRMSE(pred, true) = RMS(pred - true) / (max(true) - min(true))``; accuracy = 1 - NRMSE;
  R^2 = 1 - SS_res / SS_tot.
- Force accuracy over the whole trace and three regions of the instantaneous gap ``z``:
  repulsive ``z <= a0``, attractive ``z > a0 + w``, near ``a0`` ``|z - a0| <= w``. Every regional
  NRMSE is normalised by the range of the TRUE force over the WHOLE trace (not the region's
  own range), so regional accuracies are comparable with each other and with the whole-trace
  value (a region where the force hardly varies would otherwise get an arbitrarily large
  NRMSE from a tiny error). R^2 is regional (uses the region's own variance).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_NEAR_A0_FRACTION",
    "accuracy",
    "coefficient_errors",
    "force_accuracy",
    "nrmse",
    "r2",
    "valid_prediction_time",
]

#: default half-width ``w`` of the "near a0" band, as a fraction of ``a0``
DEFAULT_NEAR_A0_FRACTION = 0.25


def _pair(pred: ArrayLike, true: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    p = np.asarray(pred, dtype=float)
    t = np.asarray(true, dtype=float)
    if p.shape != t.shape:
        raise ValueError(f"pred and true must have the same shape, got {p.shape} and {t.shape}")
    if t.size == 0:
        raise ValueError("pred and true must not be empty")
    return p, t


def nrmse(pred: ArrayLike, true: ArrayLike, *, scale: float | None = None) -> float:
    """Normalised RMS error ``RMS(pred - true) / (max(true) - min(true))``.

    Parameters
    ----------
    pred, true : array-like, same shape
        Prediction and truth (any unit); NaN pairs are ignored.
    scale : float, optional
        Normalisation instead of the range of ``true`` (e.g. a whole-trace range), > 0.

    Returns
    -------
    float
        NRMSE [-]; ``inf`` if the normalisation is 0 and the error is not, NaN if no finite
        pair remains.
    """
    p, t = _pair(pred, true)
    ok = np.isfinite(p) & np.isfinite(t)
    if not ok.any():
        return math.nan
    err = math.sqrt(float(np.mean((p[ok] - t[ok]) ** 2)))
    if scale is None:
        scale = float(np.ptp(t[ok]))
    elif not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
    if scale == 0:
        return 0.0 if err == 0 else math.inf
    return err / scale


def accuracy(pred: ArrayLike, true: ArrayLike, *, scale: float | None = None) -> float:
    """``1 - nrmse(pred, true)`` (can be negative for very bad predictions)."""
    return 1.0 - nrmse(pred, true, scale=scale)


def r2(pred: ArrayLike, true: ArrayLike) -> float:
    """Coefficient of determination ``1 - sum (pred - true)^2 / sum (true - mean(true))^2``.

    NaN pairs are ignored; NaN when ``true`` is constant.
    """
    p, t = _pair(pred, true)
    ok = np.isfinite(p) & np.isfinite(t)
    if not ok.any():
        return math.nan
    p, t = p[ok], t[ok]
    ss_tot = float(np.sum((t - t.mean()) ** 2))
    if ss_tot == 0:
        return math.nan
    return 1.0 - float(np.sum((p - t) ** 2)) / ss_tot


def force_accuracy(f_pred: ArrayLike, f_true: ArrayLike, z: ArrayLike, a0: float, *,
                   w: float | None = None) -> dict[str, dict[str, float]]:
    """Force accuracy over the whole trace and the regions of ``design.md`` section 4.

    Parameters
    ----------
    f_pred, f_true : array-like, shape (n,)
        Predicted and true tip-sample force (same unit, > 0 repulsive). NaN predictions
        (undefined samples) are left out.
    z : array-like, shape (n,)
        True instantaneous gap (same length unit as ``a0``).
    a0 : float
        Contact onset (intermolecular distance), > 0.
    w : float, optional
        Half-width of the "near a0" band; default ``0.25 * a0``
        (`DEFAULT_NEAR_A0_FRACTION`): the transition where the force switches from the
        attractive to the contact law, narrow enough that the contact law is not yet dominant.

    Returns
    -------
    dict
        Keys ``whole``, ``repulsive`` (``z <= a0``), ``attractive`` (``z > a0 + w``),
        ``near_a0`` (``|z - a0| <= w``); each a dict with ``nrmse``, ``accuracy``, ``r2`` and
        ``n`` (number of samples). NRMSE uses the range of ``f_true`` over the whole trace.
        Empty regions give NaN metrics and ``n = 0``.
    """
    p, t = _pair(f_pred, f_true)
    z = np.asarray(z, dtype=float)
    if z.shape != t.shape:
        raise ValueError(f"z must have the shape of f_true {t.shape}, got {z.shape}")
    if not (math.isfinite(a0) and a0 > 0):
        raise ValueError(f"a0 must be a finite number > 0, got {a0!r}")
    if w is None:
        w = DEFAULT_NEAR_A0_FRACTION * a0
    elif not (math.isfinite(w) and w >= 0):
        raise ValueError(f"w must be a finite number >= 0, got {w!r}")
    scale = float(np.ptp(t))
    regions = {
        "whole": np.ones(t.shape, dtype=bool),
        "repulsive": z <= a0,
        "attractive": z > a0 + w,
        "near_a0": np.abs(z - a0) <= w,
    }
    out: dict[str, dict[str, float]] = {}
    for name, mask in regions.items():
        mask = mask & np.isfinite(p)
        n = int(mask.sum())
        if n == 0 or scale == 0:
            out[name] = {"nrmse": math.nan, "accuracy": math.nan, "r2": math.nan, "n": n}
            continue
        e = nrmse(p[mask], t[mask], scale=scale)
        out[name] = {"nrmse": e, "accuracy": 1.0 - e, "r2": r2(p[mask], t[mask]), "n": n}
    return out


def valid_prediction_time(nrmse_per_period: ArrayLike, threshold: float = 0.1) -> int:
    """Number of predicted periods before the per-period NRMSE first exceeds ``threshold``.

    Parameters
    ----------
    nrmse_per_period : array-like, shape (n_periods,)
        NRMSE of each predicted period, in order (NaN counts as exceeding).
    threshold : float, default 0.1
        > 0.

    Returns
    -------
    int
        Index of the first period with NRMSE > threshold (= number of valid periods);
        ``n_periods`` if none exceeds it.
    """
    e = np.asarray(nrmse_per_period, dtype=float)
    if e.ndim != 1:
        raise ValueError(f"nrmse_per_period must be 1-D, got shape {e.shape}")
    if not (math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be a finite number > 0, got {threshold!r}")
    bad = np.flatnonzero(~(e <= threshold))
    return int(bad[0]) if bad.size else int(e.size)


def coefficient_errors(est: Mapping[str, float], true: Mapping[str, float]) -> dict[str, Any]:
    """Compare estimated with true equation coefficients, term by term.

    Parameters
    ----------
    est, true : mapping of str to float
        Coefficients by term name; a term absent from a mapping counts as 0.

    Returns
    -------
    dict
        ``terms``: for every term in either mapping, ``{"est", "true", "abs_error",
        "rel_error"}`` (``rel_error = |est - true| / |true|``, NaN when true is 0);
        ``max_rel_error`` and ``mean_rel_error`` over the true (non-zero) terms;
        ``missing`` (true terms estimated as 0), ``spurious`` (non-zero estimates of terms
        that are 0 or absent in truth), ``support_exact`` (both empty).
    """
    names = sorted(set(est) | set(true))
    terms: dict[str, dict[str, float]] = {}
    rel: list[float] = []
    missing, spurious = [], []
    for name in names:
        e = float(est.get(name, 0.0))
        t = float(true.get(name, 0.0))
        rel_err = abs(e - t) / abs(t) if t != 0 else math.nan
        terms[name] = {"est": e, "true": t, "abs_error": abs(e - t), "rel_error": rel_err}
        if t != 0:
            rel.append(rel_err)
            if e == 0:
                missing.append(name)
        elif e != 0:
            spurious.append(name)
    return {
        "terms": terms,
        "max_rel_error": max(rel) if rel else math.nan,
        "mean_rel_error": float(np.mean(rel)) if rel else math.nan,
        "missing": missing,
        "spurious": spurious,
        "support_exact": not missing and not spurious,
    }
