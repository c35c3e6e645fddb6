"""Mode-coupling flag and sweet-spot interval from the per-window scores of the coupling head.

The coupling head of :class:`afmlearn.qrnn.module.OrbitModule` gives, for each window (one
period of input), a probability in [0, 1] that modes >= 2 carry a significant share of the tip
motion (``coupled``) and one that the window lies in the sweet spot (``sweet``). This module
turns those window scores into the answers a user asks for:

* per trace (one sweep point, or a single recording): the score is the **mean of its window
  scores** (:func:`trace_scores`) and the flag is ``score >= threshold`` (default 0.5);
* per sweep and sweep direction: the **sweet-spot interval** is the longest contiguous run of
  points (in drive-frequency order) whose sweet score is ``>= threshold``; it is reported as the
  drive frequencies ``(low, high)`` of its first and last point, or None if no point qualifies
  (:func:`sweet_spot_interval`);
* agreement with a labelled interval: the intersection over union of the two sets of sweep
  points they contain (:func:`interval_iou`); two empty intervals agree (IoU 1).

Also here, because nothing else in the project needs it: :func:`roc_auc` (Mann--Whitney form,
ties counted one half) and :func:`directions` (split a forward/reverse sweep into monotonic runs).
Plain numpy; the drive frequency may be in any unit (dimensionless ``Omega`` or Hz).
"""

from __future__ import annotations

from typing import final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CouplingFlag",
    "trace_scores",
    "sweet_spot_interval",
    "interval_iou",
    "interval_mask",
    "roc_auc",
    "directions",
]

FloatArray = NDArray[np.float64]


def _threshold(value: float) -> float:
    value = float(value)
    if not 0.0 < value < 1.0:
        raise ValueError(f"threshold must be in (0, 1), got {value}")
    return value


@final
class CouplingFlag:
    """Score and flag per trace from window scores.

    Parameters
    ----------
    threshold : float, default 0.5
        A trace is flagged coupled when its mean window score is ``>= threshold``; in (0, 1).
    """

    def __init__(self, *, threshold: float = 0.5) -> None:
        self.threshold = _threshold(threshold)

    def __call__(self, window_scores: ArrayLike, groups: ArrayLike
                 ) -> tuple[NDArray[np.int64], FloatArray, NDArray[np.bool_]]:
        """Per-trace ``(group ids, scores, flags)``; see :func:`trace_scores`."""
        ids, scores = trace_scores(window_scores, groups)
        return ids, scores, scores >= self.threshold

    def __repr__(self) -> str:
        return f"CouplingFlag(threshold={self.threshold})"


def trace_scores(window_scores: ArrayLike, groups: ArrayLike
                 ) -> tuple[NDArray[np.int64], FloatArray]:
    """Mean window score per trace.

    Parameters
    ----------
    window_scores : array-like, shape (n_windows,)
        Scores in [0, 1].
    groups : array-like of int, shape (n_windows,)
        Trace (sweep point) id of each window.

    Returns
    -------
    ids : ndarray of int, shape (n_traces,)
        Sorted unique trace ids.
    scores : ndarray, shape (n_traces,)
        Mean score of the windows of each trace.
    """
    s = np.asarray(window_scores, dtype=float).ravel()
    g = np.asarray(groups).ravel()
    if s.shape != g.shape:
        raise ValueError(f"window_scores and groups must have the same length, got {s.shape} "
                         f"and {g.shape}")
    if s.size == 0:
        raise ValueError("window_scores must not be empty")
    if not np.all(np.isfinite(s)) or s.min() < 0.0 or s.max() > 1.0:
        raise ValueError("window_scores must be finite and in [0, 1]")
    ids, inverse = np.unique(g, return_inverse=True)
    scores = np.bincount(inverse, weights=s) / np.bincount(inverse)
    return ids.astype(np.int64), scores


def directions(omega: ArrayLike) -> list[slice]:
    """Split a sweep's drive frequencies into maximal monotonic runs (forward, reverse, ...).

    A repeated frequency at a turning point (forward sweep ending at ``f``, reverse sweep
    starting at ``f``) starts the new run.

    Parameters
    ----------
    omega : array-like, shape (n_points,)
        Drive frequency of each point in recording order.

    Returns
    -------
    list of slice
        Consecutive slices covering ``0 .. n_points``.
    """
    w = np.asarray(omega, dtype=float).ravel()
    if w.size == 0:
        return []
    d = np.sign(np.diff(w))
    out: list[slice] = []
    start, sign = 0, 0.0
    for i in range(1, w.size):
        step = d[i - 1]
        if step == 0:
            ahead = d[i:][d[i:] != 0]
            if sign != 0 and ahead.size and ahead[0] == -sign:
                out.append(slice(start, i))
                start, sign = i, 0.0
            continue
        if sign == 0 or step == sign:
            sign = step
            continue
        out.append(slice(start, i))
        start, sign = i, 0.0
    out.append(slice(start, w.size))
    return out


def sweet_spot_interval(omega: ArrayLike, scores: ArrayLike, *, threshold: float = 0.5
                        ) -> tuple[float, float] | None:
    """Sweet-spot interval of one sweep direction: longest run of points with score >= threshold.

    Parameters
    ----------
    omega : array-like, shape (n_points,)
        Drive frequency of each point (any order; sorted here).
    scores : array-like, shape (n_points,)
        Sweet-spot score (or 0/1 label) of each point.
    threshold : float, default 0.5
        In (0, 1).

    Returns
    -------
    (low, high) or None
        Drive frequencies of the first and last point of the longest run (ties: the run of
        larger mean score); None when no point reaches the threshold.
    """
    w = np.asarray(omega, dtype=float).ravel()
    s = np.asarray(scores, dtype=float).ravel()
    if w.shape != s.shape:
        raise ValueError(f"omega and scores must have the same length, got {w.shape} and "
                         f"{s.shape}")
    threshold = _threshold(threshold)
    order = np.argsort(w, kind="stable")
    w, s = w[order], s[order]
    on = s >= threshold
    best: tuple[int, float, int, int] | None = None
    i = 0
    while i < w.size:
        if not on[i]:
            i += 1
            continue
        j = i
        while j + 1 < w.size and on[j + 1]:
            j += 1
        key = (j - i + 1, float(s[i : j + 1].mean()), i, j)
        if best is None or key[:2] > best[:2]:
            best = key
        i = j + 1
    if best is None:
        return None
    return float(w[best[2]]), float(w[best[3]])


def interval_mask(omega: ArrayLike, interval: tuple[float, float] | None) -> NDArray[np.bool_]:
    """Which points lie in ``interval`` (closed; a relative tolerance of 1e-12 on the ends)."""
    w = np.asarray(omega, dtype=float).ravel()
    if interval is None:
        return np.zeros(w.shape, dtype=bool)
    lo, hi = interval
    tol = 1e-12 * max(abs(lo), abs(hi), 1e-300)
    return (w >= lo - tol) & (w <= hi + tol)


def interval_iou(omega: ArrayLike, predicted: tuple[float, float] | None,
                 labelled: tuple[float, float] | None) -> float:
    """Intersection over union of the sweep points inside two intervals.

    Parameters
    ----------
    omega : array-like, shape (n_points,)
        Drive frequencies of the sweep direction the intervals belong to.
    predicted, labelled : (low, high) or None
        Intervals in the unit of ``omega``; None means "no sweet spot".

    Returns
    -------
    float
        In [0, 1]; 1 when both intervals contain no point.
    """
    a = interval_mask(omega, predicted)
    b = interval_mask(omega, labelled)
    union = int(np.sum(a | b))
    if union == 0:
        return 1.0
    return float(np.sum(a & b)) / union


def roc_auc(labels: ArrayLike, scores: ArrayLike) -> float:
    """Area under the ROC curve: P(score of a random positive > that of a random negative).

    Ties count one half (Mann--Whitney U / (n_pos n_neg)). NaN when one class is absent.

    Parameters
    ----------
    labels : array-like of {0, 1}, shape (n,)
    scores : array-like, shape (n,)
    """
    y = np.asarray(labels).ravel().astype(bool)
    s = np.asarray(scores, dtype=float).ravel()
    if y.shape != s.shape:
        raise ValueError(f"labels and scores must have the same length, got {y.shape} and "
                         f"{s.shape}")
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(s, kind="mergesort")
    ranks = np.empty(s.size, dtype=float)
    sorted_s = s[order]
    # average ranks of ties (1-based)
    _, first, counts = np.unique(sorted_s, return_index=True, return_counts=True)
    avg = first + (counts + 1) / 2.0
    ranks[order] = np.repeat(avg, counts)
    u = ranks[y].sum() - n_pos * (n_pos + 1) / 2.0
    return float(u / (n_pos * n_neg))
