"""Figures of an FM frequency-shift analysis (matplotlib, Agg canvas, PNGs written atomically).

`plot_fm_map`
    Δf(z, V) measured, as the fitted law predicts it, and the residual (three maps).
`plot_fm_curves`
    Δf against the piezo position at a few biases: data and fitted law (and the baseline).
`plot_fm_cpd`
    The per-position Kelvin-parabola CPD against z with its standard error, the model's own
    vertex, the fitted apex ``V_cpd`` with its interval, the far-field ``V_far`` and a
    reference value; and the ``V_cpd`` profile.
`fm_figures`
    All three (the figure writer of ``scripts/analyze_fm.py``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from afmlearn.fm.fit import model_hz
from afmlearn.fm.model import FMLaw
from afmlearn.io.instruments.fm_table import FMSpectroscopy
from afmlearn.plots.trace import _save

__all__ = ["fm_figures", "plot_fm_cpd", "plot_fm_curves", "plot_fm_map"]


def _law(entry: dict[str, Any]) -> FMLaw:
    return FMLaw(**entry["law"])


def plot_fm_map(report: dict[str, Any], spec: FMSpectroscopy, path: Path) -> Path:
    """Three maps: data, model (final law), residual; the fit window's edge marked."""
    law = _law(report["final"])
    model = model_hz(spec, law)
    res = spec.frequency_shift_hz - model
    z_nm = spec.z_piezo_m * 1e9
    ext = [spec.bias_v.min(), spec.bias_v.max(), z_nm.min(), z_nm.max()]
    order = np.argsort(spec.bias_v)
    fig = Figure(figsize=(13, 4.2))
    lim = np.percentile(np.abs(spec.frequency_shift_hz), 99)
    edge = z_nm.min() + report["window"]["exclude_closest_m"] * 1e9
    for k, (title, img, cl) in enumerate((("measured Δf [Hz]", spec.frequency_shift_hz, lim),
                                          ("fitted law Δf [Hz]", model, lim),
                                          ("residual [Hz]", res, 3.0))):
        ax = fig.add_subplot(1, 3, k + 1)
        im = ax.imshow(img[:, order], origin="lower", aspect="auto", extent=ext,
                       cmap="RdBu_r", vmin=-cl, vmax=cl, interpolation="nearest")
        ax.axhline(edge, color="k", lw=0.8, ls="--")
        ax.set_xlabel("bias V [V]")
        ax.set_ylabel("z piezo [nm]")
        ax.set_title(title)
        fig.colorbar(im, ax=ax)
    fig.suptitle("Δf(z, V): data vs joint law (dashed: fit window edge; rows below not fitted)")
    fig.tight_layout()
    return _save(fig, path)


def plot_fm_curves(report: dict[str, Any], spec: FMSpectroscopy, path: Path,
                   biases: tuple[float, ...] = (-10.0, -5.0, 0.0, 1.75, 5.0, 10.0)) -> Path:
    """Δf(z) at a few biases: data (dots), final law (lines), baseline (dotted)."""
    law = _law(report["final"])
    base = _law(report["baseline"])
    model, bmodel = model_hz(spec, law), model_hz(spec, base)
    z_nm = spec.z_piezo_m * 1e9
    fig = Figure(figsize=(7, 4.8))
    ax = fig.add_subplot(1, 1, 1)
    for k, v in enumerate(biases):
        j = int(np.argmin(np.abs(spec.bias_v - v)))
        color = f"C{k}"
        ax.plot(z_nm, spec.frequency_shift_hz[:, j], ".", ms=3, color=color,
                label=f"{spec.bias_v[j]:.2f} V")
        ax.plot(z_nm, model[:, j], "-", color=color, lw=1)
    ax.plot(z_nm, bmodel[:, 0], "k:", lw=1.2, label="baseline (no electrostatics)")
    ax.axvline(z_nm.min() + report["window"]["exclude_closest_m"] * 1e9, color="0.5", lw=0.8,
               ls="--", label="fit window edge")
    ax.set_ylim(np.percentile(spec.frequency_shift_hz, 0.5) - 5, 60)
    ax.set_xlabel("z piezo [nm] (larger = further)")
    ax.set_ylabel("Δf [Hz]")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Δf(z) at fixed bias: data (dots) and joint law (lines)")
    fig.tight_layout()
    return _save(fig, path)


def plot_fm_cpd(report: dict[str, Any], spec: FMSpectroscopy, path: Path) -> Path:
    """CPD against z (Kelvin parabolas, model vertex, joint V_cpd) and the V_cpd profile."""
    kel = report["kelvin"]
    z_nm = np.asarray(kel["z_piezo_m"]) * 1e9
    v = np.asarray(kel["vcpd_v"], float)
    se = np.asarray(kel["vcpd_se_v"], float)
    vc = report["vcpd"]
    fig = Figure(figsize=(11, 4.2))
    ax = fig.add_subplot(1, 2, 1)
    ax.errorbar(z_nm, v, yerr=se, fmt=".", ms=3, lw=0.6, label="Kelvin parabola per z")
    ax.plot(z_nm, np.asarray(kel["model_vcpd_v"], float), "-", label="vertex of the fitted law")
    ax.axhline(vc["value_v"], color="C2", label=f"joint apex V_cpd {vc['value_v']:.3f} V")
    lo, hi = vc["interval_95_v"]
    if lo is not None and hi is not None:
        ax.axhspan(lo, hi, color="C2", alpha=0.2)
    ax.axhline(vc["far_v"], color="C3", ls="--", label=f"far-field V_far {vc['far_v']:.2f} V")
    if vc.get("reference_v") is not None:
        ax.axhline(vc["reference_v"], color="k", ls=":", label=f"reference {vc['reference_v']} V")
    finite = np.isfinite(v)
    if finite.any():
        ax.set_ylim(np.nanpercentile(v, 2) - 0.3, np.nanpercentile(v, 98) + 0.3)
    ax.set_xlabel("z piezo [nm]")
    ax.set_ylabel("CPD [V]")
    ax.legend(fontsize=7)
    ax2 = fig.add_subplot(1, 2, 2)
    prof = vc["profile"]
    ax2.plot(prof["grid_v"], prof["delta_chi2"], "o-")
    ax2.axhline(3.84, color="k", ls=":")
    ax2.set_xlabel("V_cpd [V]")
    ax2.set_ylabel("Δχ² (profile)")
    ax2.set_title("profile of the joint V_cpd")
    fig.tight_layout()
    return _save(fig, path)


def fm_figures(report: dict[str, Any], spec: FMSpectroscopy, out_dir: Path) -> list[Path]:
    """All figures into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    return [plot_fm_map(report, spec, out / "fm_map.png"),
            plot_fm_curves(report, spec, out / "fm_curves.png"),
            plot_fm_cpd(report, spec, out / "fm_cpd.png")]
