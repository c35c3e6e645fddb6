"""Calibrated mode-coupling probability and a flag threshold for a stated false-flag rate.

The coupling head of :class:`~afmlearn.qrnn.module.OrbitModule` gives a score per window; a
trace's (set-point's, sweep point's) raw score is the mean of its window scores
(:func:`afmlearn.qrnn.coupling.trace_scores`). That raw score ranks traces well but is not a
probability: on recordings unlike the training data it can sit far below 0.5 for every coupled
trace (issue 15). This module turns it into

* a **calibrated probability** ``P(coupled | raw score)``, fitted on held-out traces (the
  validation cantilevers, never seen in training) by a calibrator object:
  `PlattCalibrator` (logistic regression on ``logit(raw score)``, Platt 1999, with Platt's
  smoothed targets; default) or `IsotonicCalibrator` (pool-adjacent-violators, Zadrozny & Elkan
  2002); both are monotone non-decreasing in the raw score, so the ranking (AUC) is unchanged;
* a **flag threshold** chosen on the same calibration set for a stated false-flag rate
  (`flag_threshold`): at most ``floor(rate * n_negatives)`` uncoupled calibration traces reach it
  (flag = ``probability >= threshold``);

bundled as `CouplingCalibration`, which is stored inside the checkpoint (plain JSON types under
the key ``calibration`` of the afmlearn metadata) and read back by
:func:`afmlearn.qrnn.infer.load_module`.

Plain numpy; scores, probabilities and thresholds are dimensionless in [0, 1].
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "AbstractCalibrator",
    "PlattCalibrator",
    "IsotonicCalibrator",
    "CouplingCalibration",
    "calibrator_from_dict",
    "flag_threshold",
    "reliability_curve",
    "expected_calibration_error",
]

FloatArray = NDArray[np.float64]
#: raw scores are clipped to [EPS, 1 - EPS] before the logit (float32 window scores of
#: confidently uncoupled traces reach ~1e-30; clipping them ties them, so the false-flag
#: threshold may be conservative, but keeps the probabilities representable)
EPS = 1e-6


def _scores(name: str, values: ArrayLike) -> FloatArray:
    s = np.asarray(values, dtype=float).ravel()
    if s.size == 0 or not np.all(np.isfinite(s)) or s.min() < 0.0 or s.max() > 1.0:
        raise ValueError(f"{name} must be a non-empty array of finite values in [0, 1]")
    return s


def _labels(values: ArrayLike, n: int) -> NDArray[np.bool_]:
    y = np.asarray(values).ravel()
    if y.shape != (n,):
        raise ValueError(f"labels must have the length of the scores ({n}), got {y.shape}")
    if not np.all(np.isin(y, (0, 1, False, True))):
        raise ValueError("labels must be 0/1 (or bool)")
    return y.astype(bool)


def _sigmoid(z: FloatArray) -> FloatArray:
    """Logistic function without overflow warnings."""
    return np.exp(-np.logaddexp(0.0, -z))


def _logit(p: FloatArray) -> FloatArray:
    p = np.clip(p, EPS, 1.0 - EPS)
    return np.log(p) - np.log1p(-p)


class AbstractCalibrator(abc.ABC):
    """Monotone map from raw scores to probabilities (scikit-learn style: ``fit``/``predict``).

    Subclasses implement `_fit` (one hook) and `predict`, and store fitted attributes with a
    trailing underscore.
    """

    def fit(self, scores: ArrayLike, labels: ArrayLike) -> AbstractCalibrator:
        """Fit on raw scores (n,) in [0, 1] and 0/1 labels (n,); both classes needed."""
        s = _scores("scores", scores)
        y = _labels(labels, s.size)
        if y.all() or not y.any():
            raise ValueError("labels: calibration needs coupled and uncoupled traces, got "
                             f"{int(y.sum())} coupled of {y.size}")
        self._fit(s, y)
        return self

    @abc.abstractmethod
    def _fit(self, scores: FloatArray, labels: NDArray[np.bool_]) -> None:
        """Fit on validated arrays."""

    @abc.abstractmethod
    def predict(self, scores: ArrayLike) -> FloatArray:
        """Calibrated probabilities, same shape as ``scores`` (flattened), in [0, 1]."""

    @abc.abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types (``kind`` and the fitted parameters)."""


@final
class PlattCalibrator(AbstractCalibrator):
    """``p = sigmoid(a * logit(score) + b)``, fitted by Newton's method with a backtracking
    line search on the log-loss.

    Targets are Platt's smoothed ``(n_pos + 1) / (n_pos + 2)`` and ``1 / (n_neg + 2)``, which
    keeps ``a`` finite on separable data. ``a`` is constrained to be >= 0 (monotone).

    Attributes
    ----------
    a_, b_ : float
        Slope and offset on the logit scale.
    """

    def __init__(self, *, max_iter: int = 100) -> None:
        self.max_iter = max_iter

    def _fit(self, scores: FloatArray, labels: NDArray[np.bool_]) -> None:
        x = _logit(scores)
        n_pos, n_neg = int(labels.sum()), int((~labels).sum())
        t = np.where(labels, (n_pos + 1.0) / (n_pos + 2.0), 1.0 / (n_neg + 2.0))

        def loss(a: float, b: float) -> float:
            z = a * x + b   # cross-entropy with soft targets, stable for any z
            return float(np.sum(np.logaddexp(0.0, z) - t * z))

        a, b = 1.0, 0.0
        f = loss(a, b)
        for _ in range(int(self.max_iter)):
            p = _sigmoid(a * x + b)
            w = p * (1.0 - p)
            g = np.array([np.sum((p - t) * x), np.sum(p - t)])
            h = np.array([[np.sum(w * x * x), np.sum(w * x)], [np.sum(w * x), np.sum(w)]])
            step = np.linalg.solve(h + 1e-10 * (1.0 + np.trace(h)) * np.eye(2), g)
            lam = 1.0   # backtracking line search (Newton alone diverges once p saturates)
            while lam > 1e-10:
                a_new, b_new = a - lam * step[0], b - lam * step[1]
                f_new = loss(a_new, b_new)
                if f_new <= f - 1e-4 * lam * float(g @ step):
                    break
                lam *= 0.5
            else:
                break
            converged = abs(f - f_new) <= 1e-12 * max(1.0, abs(f))
            a, b, f = a_new, b_new, f_new
            if converged:
                break
        self.a_, self.b_ = max(float(a), 0.0), float(b)

    def predict(self, scores: ArrayLike) -> FloatArray:
        x = _logit(_scores("scores", scores))
        return _sigmoid(self.a_ * x + self.b_)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "platt", "a": self.a_, "b": self.b_}


@final
class IsotonicCalibrator(AbstractCalibrator):
    """Pool-adjacent-violators fit of ``P(coupled)`` as a non-decreasing step function of the
    score, evaluated by linear interpolation between the block means (flat outside).

    Attributes
    ----------
    x_, y_ : ndarray, shape (n_blocks,)
        Block mean scores (increasing) and block probabilities (non-decreasing).
    """

    def _fit(self, scores: FloatArray, labels: NDArray[np.bool_]) -> None:
        order = np.argsort(scores, kind="mergesort")
        xs, ys = scores[order], labels[order].astype(float)
        # blocks: [sum x, sum y, count]
        bx: list[float] = []
        by: list[float] = []
        bn: list[float] = []
        for xi, yi in zip(xs, ys, strict=True):
            bx.append(xi)
            by.append(yi)
            bn.append(1.0)
            while len(by) > 1 and by[-2] / bn[-2] >= by[-1] / bn[-1]:
                x_last, y_last, n_last = bx.pop(), by.pop(), bn.pop()
                bx[-1] += x_last
                by[-1] += y_last
                bn[-1] += n_last
        n = np.asarray(bn)
        self.x_ = np.asarray(bx) / n
        self.y_ = np.asarray(by) / n

    def predict(self, scores: ArrayLike) -> FloatArray:
        s = _scores("scores", scores)
        return np.interp(s, self.x_, self.y_)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "isotonic", "x": self.x_.tolist(), "y": self.y_.tolist()}


def calibrator_from_dict(data: dict[str, Any]) -> AbstractCalibrator:
    """Rebuild a fitted calibrator from `AbstractCalibrator.to_dict`."""
    kind = data.get("kind")
    if kind == "platt":
        cal = PlattCalibrator()
        cal.a_, cal.b_ = float(data["a"]), float(data["b"])
        return cal
    if kind == "isotonic":
        cal = IsotonicCalibrator()
        cal.x_ = np.asarray(data["x"], dtype=float)
        cal.y_ = np.asarray(data["y"], dtype=float)
        return cal
    raise ValueError(f"calibration kind must be 'platt' or 'isotonic', got {kind!r}")


def flag_threshold(probabilities: ArrayLike, labels: ArrayLike, *,
                   false_flag_rate: float = 0.05) -> float:
    """Lowest threshold whose false-flag rate on a calibration set is at most the given rate.

    Parameters
    ----------
    probabilities : array-like, shape (n,)
        Calibrated probabilities of the calibration traces.
    labels : array-like of 0/1, shape (n,)
        Truth (only the uncoupled traces, label 0, are used).
    false_flag_rate : float
        Allowed share of uncoupled traces flagged, in (0, 1).

    Returns
    -------
    float
        ``t`` such that ``mean(p[neg] >= t) <= false_flag_rate``: just above the
        ``(k + 1)``-th largest negative probability, ``k = floor(rate * n_neg)``.
    """
    p = _scores("probabilities", probabilities)
    y = _labels(labels, p.size)
    rate = float(false_flag_rate)
    if not 0.0 < rate < 1.0:
        raise ValueError(f"false_flag_rate must be in (0, 1), got {false_flag_rate!r}")
    neg = np.sort(p[~y])[::-1]
    if neg.size == 0:
        raise ValueError("labels: the calibration set holds no uncoupled trace")
    k = int(math.floor(rate * neg.size))
    if k >= neg.size:
        return float(neg[-1])
    return float(min(np.nextafter(neg[k], np.inf), 1.0))


def reliability_curve(probabilities: ArrayLike, labels: ArrayLike, *, n_bins: int = 10
                      ) -> dict[str, FloatArray]:
    """Observed coupled fraction per bin of predicted probability (equal-width bins).

    Returns
    -------
    dict
        ``mean_predicted``, ``observed``, ``count`` (n_bins,) (NaN for empty bins).
    """
    p = _scores("probabilities", probabilities)
    y = _labels(labels, p.size).astype(float)
    edges = np.linspace(0.0, 1.0, int(n_bins) + 1)
    idx = np.clip(np.digitize(p, edges[1:-1]), 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_p = np.bincount(idx, weights=p, minlength=n_bins) / count
        obs = np.bincount(idx, weights=y, minlength=n_bins) / count
    return {"mean_predicted": mean_p, "observed": obs, "count": count}


def expected_calibration_error(probabilities: ArrayLike, labels: ArrayLike, *,
                               n_bins: int = 10) -> float:
    """Count-weighted mean |observed - predicted| over the reliability bins."""
    r = reliability_curve(probabilities, labels, n_bins=n_bins)
    ok = r["count"] > 0
    w = r["count"][ok] / r["count"][ok].sum()
    return float(np.sum(w * np.abs(r["observed"][ok] - r["mean_predicted"][ok])))


@final
@dataclass
class CouplingCalibration:
    """A fitted calibrator and the flag threshold for a stated false-flag rate.

    Parameters
    ----------
    calibrator : AbstractCalibrator
        Fitted map raw trace score -> probability.
    threshold : float
        Flag = ``probability >= threshold``.
    false_flag_rate : float
        The rate the threshold was chosen for.
    source : dict
        What it was fitted on (counts, split, measured rates).
    """

    calibrator: AbstractCalibrator
    threshold: float
    false_flag_rate: float
    source: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def fit(cls, scores: ArrayLike, labels: ArrayLike, *,
            calibrator: AbstractCalibrator | None = None, false_flag_rate: float = 0.05,
            source: dict[str, Any] | None = None) -> CouplingCalibration:
        """Fit the calibrator on ``(scores, labels)`` and choose the threshold on the same set.

        Parameters
        ----------
        scores : array-like, shape (n,)
            Raw trace scores in [0, 1] of held-out calibration traces.
        labels : array-like of 0/1, shape (n,)
        calibrator : AbstractCalibrator, optional
            Default `PlattCalibrator`.
        false_flag_rate : float
            In (0, 1).
        """
        cal = (calibrator if calibrator is not None else PlattCalibrator()).fit(scores, labels)
        p = cal.predict(scores)
        y = np.asarray(labels).astype(bool).ravel()
        t = flag_threshold(p, y, false_flag_rate=false_flag_rate)
        info = {"n_traces": int(y.size), "n_coupled": int(y.sum()),
                "calibration_false_flag_rate": float(np.mean(p[~y] >= t)),
                "calibration_recall": float(np.mean(p[y] >= t)),
                "calibration_ece": expected_calibration_error(p, y), **(source or {})}
        return cls(calibrator=cal, threshold=t, false_flag_rate=float(false_flag_rate),
                   source=info)

    def probability(self, scores: ArrayLike) -> FloatArray:
        """Calibrated probabilities of raw trace scores."""
        return self.calibrator.predict(scores)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types (stored in the checkpoint)."""
        return {"calibrator": self.calibrator.to_dict(), "threshold": float(self.threshold),
                "false_flag_rate": float(self.false_flag_rate), "source": dict(self.source)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CouplingCalibration:
        """Inverse of `to_dict`."""
        return cls(calibrator=calibrator_from_dict(data["calibrator"]),
                   threshold=float(data["threshold"]),
                   false_flag_rate=float(data["false_flag_rate"]),
                   source=dict(data.get("source", {})))
