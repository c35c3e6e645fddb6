"""Which hidden units follow which mode: activation vs drive frequency across a sweep.

The dissertation reads mode coupling off single hidden units of its QRNN: some units rise with
the drive frequency as the 2nd mode joins the motion, one peaks inside the sweet spot. Here:

* :func:`point_activations` -- the activation of every hidden unit of the network's last layer,
  averaged over the input period of a window and then over the windows of each sweep point:
  shape ``(n_points, H)``;
* :func:`rank_units` -- for each target quantity per point (each mode's share of the tip
  motion, the drive frequency, sweet-spot membership ...) the units with the largest absolute
  Pearson correlation across the points; constant targets or units get r = 0;
* :func:`interpret_sweep` -- both for one sweep (or several pooled), returned as a
  :class:`SweepInterpretation`; :func:`afmlearn.plots.qrnn.plot_unit_activation` draws it.

Correlation is not causation: a unit correlated with the mode-2 share may equally track the
amplitude drop that comes with it. The ranking is a pointer for the eye, as in the dissertation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

__all__ = ["UnitRanking", "SweepInterpretation", "point_activations", "rank_units",
           "interpret_sweep", "pearson"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True)
class UnitRanking:
    """Units most correlated with one target quantity.

    Attributes
    ----------
    target : str
        Name of the quantity (e.g. ``"mode 2 share"``).
    units : ndarray of int, shape (top,)
        Hidden-unit indices, strongest absolute correlation first.
    r : ndarray, shape (top,)
        Pearson correlation of each unit with the target across the sweep points.
    """

    target: str
    units: NDArray[np.int64]
    r: FloatArray


@final
@dataclass(frozen=True)
class SweepInterpretation:
    """Per-point activations of one (or several pooled) sweeps and the unit rankings.

    Attributes
    ----------
    omega : ndarray, shape (n_points,)
        Drive frequency of each point (dimensionless ``Omega = f / f0``).
    activation : ndarray, shape (n_points, H)
        Mean activation of each hidden unit per point.
    targets : dict of str -> ndarray, shape (n_points,)
        Quantities the units were ranked against.
    rankings : list of UnitRanking
        One per target, in the order of ``targets``.
    sweet : ndarray of bool, shape (n_points,), optional
        Sweet-spot membership (labels), for shading the figure.
    """

    omega: FloatArray
    activation: FloatArray
    targets: dict[str, FloatArray]
    rankings: list[UnitRanking]
    sweet: NDArray[np.bool_] | None = field(default=None)


def pearson(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Pearson correlation of every column of ``a`` (n, H) with ``b`` (n,); 0 where constant."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float).ravel()
    if a.ndim != 2 or a.shape[0] != b.size:
        raise ValueError(f"a must have shape (n, H) with n = len(b) = {b.size}, got {a.shape}")
    da = a - a.mean(axis=0)
    db = b - b.mean()
    na = np.sqrt((da**2).sum(axis=0))
    nb = float(np.sqrt((db**2).sum()))
    scale = 1e-12 * max(float(np.abs(a).max(initial=0.0)), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (da * db[:, None]).sum(axis=0) / (na * nb)
    ok = (na > scale * np.sqrt(b.size)) & (nb > 1e-12 * max(float(np.abs(b).max()), 1e-300))
    return np.where(ok & np.isfinite(r), r, 0.0)


def point_activations(module: Any, x: torch.Tensor | ArrayLike, point: ArrayLike
                      ) -> tuple[NDArray[np.int64], FloatArray]:
    """Mean hidden activation per sweep point.

    Parameters
    ----------
    module : OrbitModule
        Trained module (its ``predict_windows`` gives the per-window mean activation).
    x : Tensor or array-like, shape (n_windows, P, F)
        Network inputs of the windows.
    point : array-like of int, shape (n_windows,)
        Sweep point of each window.

    Returns
    -------
    ids : ndarray of int, shape (n_points,)
        Sorted point ids.
    activation : ndarray, shape (n_points, H)
    """
    xt = torch.as_tensor(np.asarray(x) if not isinstance(x, torch.Tensor) else x,
                         dtype=torch.float32)
    act = module.predict_windows(xt)["activation"].numpy().astype(float)
    p = np.asarray(point).ravel()
    if p.size != act.shape[0]:
        raise ValueError(f"point must have one entry per window ({act.shape[0]}), got {p.size}")
    ids, inverse = np.unique(p, return_inverse=True)
    sums = np.zeros((ids.size, act.shape[1]))
    np.add.at(sums, inverse, act)
    return ids.astype(np.int64), sums / np.bincount(inverse)[:, None]


def rank_units(activation: ArrayLike, targets: Mapping[str, ArrayLike], *, top: int = 3
               ) -> list[UnitRanking]:
    """Units with the largest |Pearson r| against each target.

    Parameters
    ----------
    activation : array-like, shape (n_points, H)
    targets : mapping of str -> array-like, shape (n_points,)
    top : int, default 3
        Units kept per target, in [1, H].
    """
    a = np.asarray(activation, dtype=float)
    if a.ndim != 2 or a.shape[0] < 3:
        raise ValueError(f"activation must have shape (n_points >= 3, H), got {a.shape}")
    if not 1 <= int(top) <= a.shape[1]:
        raise ValueError(f"top must be in [1, {a.shape[1]}], got {top}")
    out = []
    for name, values in targets.items():
        r = pearson(a, values)
        order = np.argsort(-np.abs(r), kind="stable")[: int(top)]
        out.append(UnitRanking(target=str(name), units=order.astype(np.int64), r=r[order]))
    return out


def interpret_sweep(module: Any, x: torch.Tensor | ArrayLike, *, point: ArrayLike,
                    omega: ArrayLike, shares: ArrayLike, sweet: ArrayLike | None = None,
                    top: int = 3) -> SweepInterpretation:
    """Activations per point and unit rankings against each mode's share and the frequency.

    Parameters
    ----------
    module : OrbitModule
    x : Tensor or array-like, shape (n_windows, P, F)
        Inputs of the windows of the sweep(s).
    point, omega : array-like, shape (n_windows,)
        Sweep point and drive frequency ``Omega`` of each window.
    shares : array-like, shape (n_windows, n_modes)
        Share of each mode in the tip motion (labels of the data set).
    sweet : array-like, shape (n_windows,), optional
        Sweet-spot membership; adds the target ``"sweet spot"``.
    top : int, default 3
        Units per target.

    Returns
    -------
    SweepInterpretation
        Targets ``"mode k share"`` for every mode whose share varies, ``"drive frequency"`` and
        (with ``sweet``) ``"sweet spot"``; points sorted by drive frequency.
    """
    ids, act = point_activations(module, x, point)
    p = np.asarray(point).ravel()
    first = np.unique(p, return_index=True)[1]
    w = np.asarray(omega, dtype=float).ravel()[first]
    sh = np.asarray(shares, dtype=float).reshape(p.size, -1)[first]
    order = np.argsort(w, kind="stable")
    w, sh, act = w[order], sh[order], act[order]
    targets: dict[str, FloatArray] = {}
    for m in range(sh.shape[1]):
        if np.ptp(sh[:, m]) > 0:
            targets[f"mode {m + 1} share"] = sh[:, m]
    targets["drive frequency"] = w
    sw = None
    if sweet is not None:
        sw = (np.asarray(sweet, dtype=float).ravel()[first] > 0.5)[order]
        if sw.any() and not sw.all():
            targets["sweet spot"] = sw.astype(float)
    return SweepInterpretation(omega=w, activation=act, targets=targets,
                               rankings=rank_units(act, targets, top=top), sweet=sw)
