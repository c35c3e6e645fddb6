"""Figures of a lock-in curve diagnosis (matplotlib, Agg canvas, PNGs written atomically).

`plot_curve_fit`
    Measured amplitude and phase against piezo position (approach and retraction) with the
    baseline and extended models' predictions (the retraction is held out).
`plot_curve_force`
    The fitted conservative force laws against the gap (baseline and extended).
`plot_curve_dissipation`
    Energy dissipated per cycle from amplitude and phase (Cleveland/Anczykowski).
`curve_figures`
    All three (the figure writer of ``scripts/analyze_curves.py``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from afmlearn.curves import CurveDiagnoser
from afmlearn.io._atomic import atomic_path

__all__ = ["plot_curve_fit", "plot_curve_force", "plot_curve_dissipation", "curve_figures",
           "plot_parameter_spread"]


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path


def plot_curve_fit(diag: CurveDiagnoser, path: str | os.PathLike[str]) -> Path:
    """Amplitude [nm] and phase [deg] against piezo position [nm], data and models."""
    c = diag.curve_
    nm = c.length_m * 1e9
    fig = Figure(figsize=(7.5, 6.0))
    ax_a, ax_p = fig.subplots(2, 1, sharex=True)
    preds = {"baseline": diag.baseline_.predict(c)}
    if diag.cause_ != "none":
        preds[f"extended ({diag.cause_})"] = diag.extended_.predict(c)
    for seg, name, colour in ((0, "approach (fitted)", "#1f77b4"),
                              (1, "retraction (held out)", "#ff7f0e")):
        m = c.segment == seg
        ax_a.plot(c.z_piezo[m] * nm, c.amplitude[m] * nm, ".", ms=2, color=colour, label=name)
        ax_p.plot(c.z_piezo[m] * nm, np.degrees(c.phase[m]), ".", ms=2, color=colour)
    for (label, (a, p)), style in zip(preds.items(), ("k-", "r--"), strict=False):
        for seg in (0, 1):
            m = c.segment == seg
            ax_a.plot(c.z_piezo[m] * nm, a[m] * nm, style, lw=1,
                      label=label if seg == 0 else None)
            ax_p.plot(c.z_piezo[m] * nm, np.degrees(p[m]), style, lw=1)
    ax_a.set_ylabel("amplitude [nm]")
    ax_p.set_ylabel("phase lag [deg]")
    ax_p.set_xlabel("piezo position [nm] (larger = further)")
    ax_a.legend(fontsize=7)
    ax_a.set_title(f"cause: {diag.cause_} (confidence {diag.confidence_:.2f}, "
                   f"held-out gain {diag.gain_:.3f})", fontsize=9)
    return _save(fig, Path(path))


def plot_curve_force(diag: CurveDiagnoser, path: str | os.PathLike[str]) -> Path:
    """Conservative force [nN] against gap [nm] of the fitted laws."""
    c = diag.curve_
    law = diag.extended_.law_
    z = np.linspace(-0.5 * law.a0 - 0.02, 0.3, 400)
    fig = Figure(figsize=(6.0, 4.0))
    ax = fig.subplots()
    for name, fit, style in (("baseline", diag.baseline_, "k-"),
                             (f"extended ({diag.cause_})", diag.extended_, "r--")):
        ax.plot(z * c.length_m * 1e9, fit.law_.conservative(z) * c.force_unit_n * 1e9, style,
                label=name)
        if diag.cause_ == "none":
            break
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel("gap z [nm]")
    ax.set_ylabel("force [nN] (> 0 repulsive)")
    ax.legend(fontsize=8)
    return _save(fig, Path(path))


def plot_curve_dissipation(diag: CurveDiagnoser, path: str | os.PathLike[str]) -> Path:
    """Energy dissipated per cycle [eV] against piezo position [nm]."""
    c = diag.curve_
    e = diag.dissipation() / 1.602176634e-19
    fig = Figure(figsize=(6.0, 4.0))
    ax = fig.subplots()
    for seg, name in ((0, "approach"), (1, "retraction")):
        m = c.segment == seg
        ax.plot(c.z_piezo[m] * c.length_m * 1e9, e[m], ".", ms=2, label=name)
    ax.set_xlabel("piezo position [nm]")
    ax.set_ylabel("dissipated energy per cycle [eV]")
    ax.legend(fontsize=8)
    return _save(fig, Path(path))


def curve_figures(diag: CurveDiagnoser, out_dir: Path) -> list[Path]:
    """The three figures into ``out_dir``."""
    out = Path(out_dir)
    return [plot_curve_fit(diag, out / "curve_fit.png"),
            plot_curve_force(diag, out / "curve_force.png"),
            plot_curve_dissipation(diag, out / "curve_dissipation.png")]


def _si_parameters(row: dict) -> dict[str, float]:
    """SI values of one row's fitted law (baseline attraction and stiffness, the extension's
    damping) from its dimensionless parameters and scales (k, f0, free amplitude)."""
    lu = row["free_amplitude_m"]
    k = row.get("spring_constant_n_per_m") or float("nan")
    w0 = 2 * np.pi * (row.get("resonance_frequency_hz") or float("nan"))
    base = row.get("baseline_parameters", row["parameters"])
    ext = row["parameters"]
    out = {"free amplitude [nm]": lu * 1e9,
           "adhesion, named model [nN]": row.get("adhesion_force_n", np.nan) * 1e9,
           "held-out gain": row["gain"] if row["cause"] != "none" else np.nan}
    # E delta^1.5 in nN / nm^1.5: stiffness * k L / L^1.5
    out["contact stiffness, baseline [nN/nm^1.5]"] = (base.get("stiffness", np.nan) * k * lu
                                                      * 1e9 / (lu * 1e9) ** 1.5)
    if ext.get("damping"):
        out["long-range damping [N s/m]"] = ext["damping"] * k / w0
        out["damping decay length [nm]"] = ext["decay_length"] * lu * 1e9
    return out


def plot_parameter_spread(rows: list[dict], out_dir: Path) -> Path:
    """Histograms of fitted parameters across curves, one colour per group (``analyze_folder``
    rows; as Fig. 5 of the dissertation: the spread of one tip's parameters across curves).

    Log-spaced bins for positive quantities spanning more than a decade.
    """
    vals = [(r.get("group", ""), _si_parameters(r)) for r in rows]
    keys = ["free amplitude [nm]", "adhesion, named model [nN]",
            "contact stiffness, baseline [nN/nm^1.5]", "long-range damping [N s/m]",
            "damping decay length [nm]", "held-out gain"]
    groups = sorted({g for g, _ in vals})
    fig = Figure(figsize=(11.0, 6.0))
    axes = fig.subplots(2, 3).ravel()
    for ax, key in zip(axes, keys, strict=True):
        data = {g: np.array([v.get(key, np.nan) for gg, v in vals if gg == g], dtype=float)
                for g in groups}
        allv = np.concatenate([d[np.isfinite(d)] for d in data.values()])
        if allv.size == 0:
            ax.set_axis_off()
            continue
        logx = bool(np.all(allv > 0) and allv.max() > 10 * allv.min())
        bins = (np.geomspace(allv.min(), allv.max(), 16) if logx
                else np.linspace(allv.min(), allv.max() + 1e-12, 16))
        ax.hist([d[np.isfinite(d)] for d in data.values()], bins=bins, stacked=True,
                label=[f"{g} ({np.isfinite(data[g]).sum()})" for g in groups])
        if logx:
            ax.set_xscale("log")
        ax.set_xlabel(key)
        ax.set_ylabel("curves")
    axes[0].legend(fontsize=8)
    causes: dict[str, int] = {}
    for r in rows:
        causes[r["cause"]] = causes.get(r["cause"], 0) + 1
    fig.suptitle(", ".join(f"{c}: {n}" for c, n in sorted(causes.items())), fontsize=9)
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "parameter_spread.png")
