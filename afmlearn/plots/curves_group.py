"""Figures of a joint diagnosis of curves of one tip (matplotlib, Agg, PNGs written atomically).

`plot_group_fit`
    Per curve: measured amplitude and phase against the rest gap of the joint fit, with the
    joint baseline's and extended law's predictions.
`plot_group_force`
    The shared conservative force laws (baseline and extended) against the gap, in SI.
`group_figures`
    Both (the figure writer of ``scripts/analyze_curves.py joint=true``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from afmlearn.curves.group_diagnose import GroupDiagnoser
from afmlearn.plots.trace import _save

__all__ = ["group_figures", "plot_group_fit", "plot_group_force"]



def plot_group_fit(diag: GroupDiagnoser, path: str | os.PathLike[str]) -> Path:
    """Amplitude / free amplitude and phase [deg] of every curve against its rest gap [nm]
    (the extended fit's surface position), data (approach and retraction) and both models."""
    curves = diag.curves_
    n = len(curves)
    fig = Figure(figsize=(3.2 * n + 1.0, 5.6))
    axes = fig.subplots(2, n, squeeze=False)
    ext = diag.extended_
    fits = {"baseline": diag.baseline_}
    if diag.cause_ != "none":
        fits[f"extended ({diag.cause_})"] = ext
    for i, c in enumerate(curves):
        nm = c.length_m * 1e9
        gap = (c.z_piezo - ext.values_["curves"][i]["offset"]) * nm
        ax_a, ax_p = axes[0, i], axes[1, i]
        for seg, name, colour in ((0, "approach (fitted)", "#1f77b4"),
                                  (1, "retraction", "#ff7f0e")):
            m = c.segment == seg
            ax_a.plot(gap[m], c.amplitude[m], ".", ms=2, color=colour, label=name)
            ax_p.plot(gap[m], np.degrees(c.phase[m]), ".", ms=2, color=colour)
        for (label, f), style in zip(fits.items(), ("k-", "r--"), strict=False):
            a, p = f.predict(i)
            for seg in (0, 1):
                m = c.segment == seg
                ax_a.plot(gap[m], a[m], style, lw=1, label=label if seg == 0 else None)
                ax_p.plot(gap[m], np.degrees(p[m]), style, lw=1)
        ax_a.set_title(f"free amplitude {nm:.1f} nm", fontsize=8)
        ax_p.set_xlabel("rest gap [nm]")
    axes[0, 0].set_ylabel("amplitude / free")
    axes[1, 0].set_ylabel("phase lag [deg]")
    axes[0, 0].legend(fontsize=6)
    fig.suptitle(f"joint fit of {n} curves: cause {diag.cause_} (confidence "
                 f"{diag.confidence_:.2f}, gain {diag.gain_:.3f})", fontsize=9)
    return _save(fig, Path(path))


def plot_group_force(diag: GroupDiagnoser, path: str | os.PathLike[str]) -> Path:
    """Conservative force [nN] against gap [nm] of the shared laws (baseline, extended)."""
    b, ext = diag.baseline_, diag.extended_
    c0 = diag.curves_[0]
    unit_nm = b.length_m_ * 1e9
    force_nn = c0.spring_constant_n_per_m * b.length_m_ * 1e9
    z = np.linspace(0.3 * b.law_.a0, 2.0, 400)  # group units
    fig = Figure(figsize=(6.0, 4.0))
    ax = fig.subplots()
    ax.plot(z * unit_nm, b.law_.conservative(z) * force_nn, "k-", lw=1, label="baseline")
    if diag.cause_ != "none":
        ax.plot(z * unit_nm, ext.law_.conservative(z) * force_nn, "r--", lw=1,
                label=f"extended ({diag.cause_})")
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xlabel("gap z [nm]")
    ax.set_ylabel("conservative force [nN] (> 0 repulsive)")
    ax.legend(fontsize=7)
    return _save(fig, Path(path))


def group_figures(diag: GroupDiagnoser, out_dir: Path) -> list[Path]:
    """Both joint-fit figures in ``out_dir``."""
    out = Path(out_dir)
    return [plot_group_fit(diag, out / "group_fit.png"),
            plot_group_force(diag, out / "group_force.png")]
