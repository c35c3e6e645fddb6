"""Figures of the QRNN: predicted vs measured orbit, coupling score vs frequency, hidden units.

`plot_prediction`
    Deflection vs time (input period, then measured and predicted periods) and the phase-space
    orbit (deflection vs its rate of change) of the predicted periods.
`plot_scores`
    Coupling and sweet-spot scores per trace vs drive frequency, the threshold and the
    sweet-spot interval(s).
`plot_reliability`
    Reliability diagram of coupling probabilities (observed coupled fraction per bin of
    predicted probability), several sets side by side, with the flag threshold.
`inference_figures`
    The figures of one inference (``prediction.png``, ``scores.png`` for sweeps), given to
    :func:`afmlearn.qrnn.infer.infer` as its figure maker by ``scripts/infer_qrnn.py``.
`plot_unit_activation`
    Mean hidden-unit activation vs drive frequency across a sweep: the modal shares on top, the
    units most correlated with each target below (``afmlearn.qrnn.interpret``).

Figures are drawn on an explicit Agg canvas (the caller's pyplot backend is untouched) and
written atomically as PNG (temporary sibling, then ``os.replace``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray
from scipy.signal import savgol_filter

from afmlearn.plots.trace import _save

__all__ = ["inference_figures", "plot_prediction", "plot_reliability", "plot_scores",
           "plot_unit_activation"]

_MEASURED, _PREDICTED, _SWEET = "#1f77b4", "#d62728", "#2ca02c"


def _rate(x: NDArray[np.float64], samples_per_period: int) -> NDArray[np.float64]:
    """d x / d(drive phase) by a Savitzky--Golay derivative (cubic, ~1/8 period window)."""
    w = max(5, (samples_per_period // 8) | 1)
    if x.size < w:
        return np.gradient(x) * samples_per_period / (2 * np.pi)
    return savgol_filter(x, w, 3, deriv=1) * samples_per_period / (2 * np.pi)


def plot_prediction(measured: ArrayLike, predicted: ArrayLike, path: str | os.PathLike[str], *,
                    samples_per_period: int, title: str = "",
                    unit: str = "input-normalised") -> Path:
    """Measured vs predicted deflection and orbit of one window.

    Parameters
    ----------
    measured : array-like, shape ((1 + horizon) * P,)
        Input period followed by the measured target periods.
    predicted : array-like, shape (horizon * P,)
        Predicted target periods.
    path : path-like
        PNG file to write.
    samples_per_period : int
        ``P``.
    title : str
    unit : str
        Unit of the deflection axis label.
    """
    m = np.asarray(measured, dtype=float).ravel()
    p = np.asarray(predicted, dtype=float).ravel()
    n_in = m.size - p.size
    if n_in <= 0 or samples_per_period < 2:
        raise ValueError("measured must be longer than predicted (input period + targets) and "
                         "samples_per_period >= 2")
    t = np.arange(m.size) / samples_per_period
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.8, 1]})
    ax.axvspan(0, n_in / samples_per_period, color="0.9", label="input period")
    ax.plot(t, m, color=_MEASURED, lw=1.2, label="measured")
    ax.plot(t[n_in:], p, color=_PREDICTED, lw=1.2, ls="--", label="predicted")
    ax.set_xlabel("time [drive periods]")
    ax.set_ylabel(f"deflection [{unit}]")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "orbit prediction from one period")
    # orbit: deflection vs d(deflection)/d(phase), per radian of the drive (smoothed derivative)
    ax2.plot(m[n_in:], _rate(m[n_in:], samples_per_period), color=_MEASURED, lw=1.0,
             label="measured")
    ax2.plot(p, _rate(p, samples_per_period), color=_PREDICTED, lw=1.0, ls="--",
             label="predicted")
    ax2.set_xlabel("deflection")
    ax2.set_ylabel("d deflection / d(drive phase) [per rad]")
    ax2.set_title("phase-space orbit (predicted periods)")
    ax2.legend(fontsize=8)
    return _save(fig, path)


def plot_reliability(curves: dict[str, dict[str, Any]], path: str | os.PathLike[str], *,
                     threshold: float | None = None, title: str = "") -> Path:
    """Reliability diagram: observed coupled fraction vs mean predicted probability per bin.

    Parameters
    ----------
    curves : dict
        Legend label -> `afmlearn.qrnn.calibration.reliability_curve` output
        (``mean_predicted``, ``observed``, ``count``; shape (n_bins,) each).
    path : path-like
    threshold : float, optional
        Flag threshold, drawn as a vertical line.
    """
    fig = Figure(figsize=(9, 4.2), layout="constrained")
    ax, axc = fig.subplots(1, 2, width_ratios=[1.3, 1])
    ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--", label="perfect calibration")
    for i, (name, r) in enumerate(curves.items()):
        ok = np.asarray(r["count"]) > 0
        mp, ob = np.asarray(r["mean_predicted"])[ok], np.asarray(r["observed"])[ok]
        n = np.asarray(r["count"])[ok]
        color = f"C{i}"
        ax.plot(mp, ob, "o-", color=color, ms=4, lw=1.2, label=name)
        centers = (np.flatnonzero(ok) + 0.5) / len(r["count"])
        axc.bar(centers + (i - 0.5 * (len(curves) - 1)) * 0.8 / len(r["count"]) / len(curves),
                n, width=0.8 / len(r["count"]) / len(curves), color=color, label=name)
    if threshold is not None:
        for a in (ax, axc):
            a.axvline(threshold, color="0.3", ls=":", lw=1)
        ax.text(threshold, 0.02, f" threshold {threshold:.3g}", fontsize=8)
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("predicted probability of coupling (bin mean)")
    ax.set_ylabel("observed coupled fraction")
    ax.set_title(title or "reliability of the coupling probability")
    ax.legend(fontsize=8, loc="upper left")
    axc.set_yscale("log")
    axc.set_xlim(0, 1)
    axc.set_xlabel("predicted probability")
    axc.set_ylabel("traces per bin")
    return _save(fig, path)


def plot_scores(frequency: ArrayLike, coupled: ArrayLike, path: str | os.PathLike[str], *,
                sweet: ArrayLike | None = None, threshold: float = 0.5,
                intervals: Sequence[tuple[float, float] | None] = (),
                labels: Sequence[str] | None = None, unit: str = "kHz",
                scale: float = 1e-3, title: str = "") -> Path:
    """Coupling (and sweet-spot) score per trace vs drive frequency.

    Parameters
    ----------
    frequency : array-like, shape (n,)
        Drive frequency of each trace [Hz] (multiplied by ``scale`` for the axis).
    coupled : array-like, shape (n,)
        Coupling score in [0, 1].
    path : path-like
    sweet : array-like, shape (n,), optional
        Sweet-spot score in [0, 1].
    threshold : float
        Flag threshold, drawn as a line.
    intervals : sequence of (low, high) or None
        Sweet-spot intervals [Hz] to shade.
    labels : sequence of str, optional
        Legend label of each interval (e.g. "forward").
    unit, scale : str, float
        Axis unit and the factor from Hz to it.
    """
    f = np.asarray(frequency, dtype=float).ravel() * scale
    c = np.asarray(coupled, dtype=float).ravel()
    fig = Figure(figsize=(8, 4), layout="constrained")
    ax = fig.subplots()
    ax.plot(f, c, "o-", ms=3, lw=1, color=_PREDICTED, label="coupling score")
    if sweet is not None:
        ax.plot(f, np.asarray(sweet, dtype=float).ravel(), "s-", ms=2.5, lw=0.8, color=_SWEET,
                label="sweet-spot score")
    ax.axhline(threshold, color="0.4", ls=":", lw=1, label=f"threshold {threshold:g}")
    for i, iv in enumerate(intervals):
        if iv is None:
            continue
        name = labels[i] if labels is not None and i < len(labels) else ""
        ax.axvspan(iv[0] * scale, iv[1] * scale, color=_SWEET, alpha=0.12 + 0.06 * i,
                   label=f"sweet spot {name}".strip())
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel(f"drive frequency [{unit}]")
    ax.set_ylabel("score")
    ax.set_title(title or "mode-coupling score vs drive frequency")
    ax.legend(fontsize=8, loc="best")
    return _save(fig, path)


def plot_unit_activation(interp: Any, path: str | os.PathLike[str], *, title: str = "",
                         max_targets: int = 4) -> Path:
    """Hidden-unit activation vs drive frequency (:class:`SweepInterpretation`).

    Top panel: the targets (mode shares, sweet-spot membership) vs ``Omega``. One panel per
    target below: the activation of its top-ranked units (with r in the legend) over the faint
    activations of all units, each unit min-max scaled across the sweep. With exactly two
    modes the mode-1 share is ``1 -`` the mode-2 share, so its panel is left out.
    """
    w = np.asarray(interp.omega, dtype=float)
    act = np.asarray(interp.activation, dtype=float)
    span = np.ptp(act, axis=0)
    scaled = (act - act.min(axis=0)) / np.where(span > 0, span, 1.0)
    names = set(interp.targets)
    two_modes = "mode 2 share" in names and "mode 3 share" not in names
    rankings = [r for r in interp.rankings
                if not (two_modes and r.target == "mode 1 share")][:max_targets]
    fig = Figure(figsize=(8, 2.2 * (1 + len(rankings))), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1 + len(rankings), 1, sharex=True))
    top = axes[0]
    for name, values in interp.targets.items():
        if name.startswith("mode"):
            top.plot(w, values, lw=1.2, label=name)
    top.set_ylabel("share of tip motion")
    top.legend(fontsize=8)
    top.set_title(title or "hidden units vs drive frequency")
    for ax, ranking in zip(axes[1:], rankings, strict=True):
        ax.plot(w, scaled, color="0.85", lw=0.5)
        for u, r in zip(ranking.units, ranking.r, strict=True):
            ax.plot(w, scaled[:, u], lw=1.4, label=f"unit {u} (r = {r:+.2f})")
        ax.set_ylabel("activation\n(scaled)")
        ax.set_title(f"units most correlated with {ranking.target}", fontsize=9)
        ax.legend(fontsize=7, loc="best")
    if interp.sweet is not None and np.any(interp.sweet):
        lo, hi = w[interp.sweet].min(), w[interp.sweet].max()
        for ax in axes:
            ax.axvspan(lo, hi, color=_SWEET, alpha=0.12)
    axes[-1].set_xlabel(r"drive frequency $\Omega = f / f_0$")
    return _save(fig, path)


def inference_figures(result: dict[str, Any], out: Path, run: dict[str, Any]) -> list[str]:
    """The figures of one QRNN inference (:func:`afmlearn.qrnn.infer.infer`'s ``figures=``).

    ``prediction.png``: predicted vs measured deflection and orbit of one window (the trace,
    or the sweep row with the highest coupling score); for sweeps also ``scores.png``
    (coupling and sweet-spot score vs drive frequency, the interval shaded).

    Parameters
    ----------
    result : dict
        Output of :func:`afmlearn.qrnn.infer.predict_trace` (``summary`` and ``arrays``;
        deflection windows normalised per input period, frequencies in Hz).
    out : Path
        Existing output folder.
    run : dict
        The checkpoint's run settings (``samples_per_period``).

    Returns
    -------
    list of str
        Paths written.
    """
    a = result["arrays"]
    win = a["windows"]
    p = int(run["samples_per_period"])
    best_row = int(a["rows"][int(np.argmax(a["score"]))])
    i = int(np.flatnonzero(win["row"] == best_row)[0])
    u_in = win["x"][i, :, 0].astype(float)
    measured = np.concatenate([u_in, win["y"][i].astype(float)])
    off, sc = float(win["offset_m"][i]), float(win["scale_m"][i])
    f = win["omega_rows"][best_row]
    title = (f"row {best_row}, " if win["is_sweep"] else "") + f"Omega = {f:.4f}"
    paths = [plot_prediction((off + sc * measured) * 1e9, (off + sc * a["pred"][i]) * 1e9,
                             out / "prediction.png", samples_per_period=p, unit="nm",
                             title=f"orbit prediction ({title})")]
    s = result["summary"]
    if s["is_sweep"]:
        ivs = [tuple(x["interval_hz"]) if x["interval_hz"] else None for x in s["sweet_spot"]]
        paths.append(plot_scores(a["frequency_hz"], a["score"], out / "scores.png",
                                 sweet=a["sweet_score"], threshold=s["threshold"],
                                 intervals=ivs, labels=[x["direction"] for x in s["sweet_spot"]]))
    return [str(q) for q in paths]
