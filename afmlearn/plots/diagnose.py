"""Figures of a diagnosis: what the baseline gets wrong, beside the extended model.

Every function takes a fitted :class:`afmlearn.diagnose.Diagnoser`, draws the baseline (left)
and the extended model (right) on one Agg figure, writes one PNG atomically and returns its
path. Units are SI at the edge: nm, nN, eV; time in drive periods.

`plot_residual`
    Held-out deflection (raw, denoised) against each model's steady orbit, and the residual.
`plot_orbit`
    Phase portraits (deflection, velocity) of measurement and model.
`plot_spectrum`
    Amplitude spectra of the held-out measurement and of each model: harmonics of the drive
    and anything between them (a second mode shows there).
`plot_force_gap`
    Force against gap on approach and retraction: the force the measured orbit implies under
    each model's lever (transfer-function inversion) and each model's own force law.
`plot_energy`
    Energy into the sample per cycle: measured (drive minus lever damping), baseline, extended.
`plot_candidates`
    Evidence (chi-square drop vs its null threshold) and held-out gain of every cause.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from afmlearn.identify.identifier import force_vs_gap
from afmlearn.plots.trace import _save

__all__ = ["plot_residual", "plot_orbit", "plot_spectrum", "plot_force_gap", "plot_energy",
           "plot_candidates", "plot_all"]

_MEAS, _BASE, _EXT = "0.55", "#1f77b4", "#d62728"


def _fig(width: float, height: float, ncols: int = 2, nrows: int = 1,
         **kw: Any) -> tuple[Figure, np.ndarray]:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_2d(fig.subplots(nrows, ncols, squeeze=False, **kw))
    return fig, axes


def _path(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def _models(dg: Any) -> list[tuple[str, str, Any, str]]:
    """(title, key of the held-out simulation, model, colour) for baseline and extension."""
    ext = "extended: " + dg.cause_ if dg.cause_ != "none" else "extended: none (= baseline)"
    return [("baseline (1 mode, VdW-DMT sphere)", "none", dg.baseline_, _BASE),
            (ext, dg.cause_, dg.extended_, _EXT)]


def plot_residual(dg: Any, path: str | os.PathLike[str], *, periods: float = 4.0) -> Path:
    """Held-out deflection [nm] vs each model's steady orbit, with the residual below."""
    h = dg.heldout_
    L = dg.calibrated_.scales.length * 1e9
    per = 2 * math.pi / dg.calibrated_.omega
    n = min(h.tau.size, int(round(periods * dg.calibrated_.samples_per_period)))
    t = (h.tau[:n] - h.tau[0]) / per
    fig, ax = _fig(11, 5.5, 2, 2, sharex=True, sharey="row")
    for j, (title, key, _, col) in enumerate(_models(dg)):
        sim = h.simulated[key][:n]
        a, b = ax[0, j], ax[1, j]
        a.plot(t, h.measured[:n] * L, ".", ms=1.5, color=_MEAS, label="measured")
        a.plot(t, h.reference[:n] * L, "-", color="k", lw=0.8, label="measured, denoised")
        a.plot(t, sim * L, "--", color=col, lw=1.2, label="model, steady orbit")
        nr = dg.baseline_nrmse_ if key == "none" else dg.extended_nrmse_
        a.set_title(f"{title}\nheld-out NRMSE {nr:.3g}", fontsize=9)
        b.plot(t, (h.reference[:n] - sim) * L, color=col, lw=0.9)
        b.axhline(0, color="k", lw=0.5)
        b.set_xlabel("time [drive periods from the held-out start]")
    ax[0, 0].set_ylabel("deflection [nm]")
    ax[1, 0].set_ylabel("denoised measured - model [nm]")
    ax[0, 0].legend(fontsize=7, loc="upper right")
    return _save(fig, _path(path))


def plot_orbit(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Phase portraits: deflection [nm] vs velocity [nm / (1/omega0)], measured vs model."""
    h = dg.heldout_
    L = dg.calibrated_.scales.length * 1e9
    n = min(h.tau.size, int(round(3 * dg.calibrated_.samples_per_period)))
    fig, ax = _fig(10, 4.5, sharex=True, sharey=True)
    for j, (title, key, _, col) in enumerate(_models(dg)):
        a = ax[0, j]
        a.plot(h.reference[:n] * L, h.reference_rate[:n] * L, color="k", lw=1.0,
               label="measured (held-out, denoised)")
        a.plot(h.simulated[key][:n] * L, h.simulated_rate[key][:n] * L, "--", color=col,
               lw=1.2, label="model")
        a.axvline(dg.orbit_.gap * L - dg.baseline_.spec.a0 * L, color="0.7", lw=0.7, ls=":")
        a.set_title(title, fontsize=9)
        a.set_xlabel("deflection [nm] (dotted: contact onset of the baseline)")
    ax[0, 0].set_ylabel("velocity [nm per 1/omega0]")
    ax[0, 0].legend(fontsize=7)
    return _save(fig, _path(path))


def _spectrum(y: np.ndarray, spp: float) -> tuple[np.ndarray, np.ndarray]:
    n_per = int(math.floor(y.size / spp))
    m = int(round(n_per * spp))
    y = y[:m] - np.mean(y[:m])
    amp = np.abs(np.fft.rfft(y * np.hanning(m))) * 2 / (0.5 * m)
    f = np.fft.rfftfreq(m, d=1.0 / spp)     # in units of the drive frequency
    return f, amp


def plot_spectrum(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Amplitude spectra [nm] of the held-out measurement and of each model's orbit."""
    h = dg.heldout_
    cal = dg.calibrated_
    L = cal.scales.length * 1e9
    spp = cal.samples_per_period
    fmax = min(dg.orbit_.n_h + 2.5, spp / 2)
    fig, ax = _fig(11, 4.5, sharey=True)
    fm, am = _spectrum(h.measured, spp)
    keep = fm <= fmax
    for j, (title, key, model, col) in enumerate(_models(dg)):
        a = ax[0, j]
        fs, as_ = _spectrum(h.simulated[key], spp)
        a.semilogy(fm[keep], am[keep] * L, color=_MEAS, lw=0.7, label="measured")
        a.semilogy(fs[fs <= fmax], np.maximum(as_[fs <= fmax] * L, 1e-12), color=col, lw=0.9,
                   label="model")
        if model.spec.mode2 is not None:
            r = model.spec.mode2[0] / cal.omega
            a.axvline(r, color=col, ls=":", lw=1, label=f"mode 2 ({r:.2f} f_drive)")
        a.set_title(f"{title}; spectral error "
                    f"{dg.spectral_error_['baseline' if key == 'none' else 'extended']:.3g}",
                    fontsize=9)
        a.set_xlabel("frequency / drive frequency")
        a.set_ylim(bottom=max(1e-6, float(np.min(am[keep][am[keep] > 0]) * L) / 3))
    ax[0, 0].set_ylabel("amplitude [nm]")
    ax[0, 0].legend(fontsize=7)
    return _save(fig, _path(path))


def plot_force_gap(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Force [nN] vs gap [nm]: measured (inverted) and model, approach and retraction."""
    o = dg.orbit_
    sc = dg.calibrated_.scales
    L, Fn = sc.length * 1e9, sc.force * 1e9
    fig, ax = _fig(11, 4.5, sharey=True)
    for j, (title, _, model, col) in enumerate(_models(dg)):
        a = ax[0, j]
        x, v, _ = o.true_orbit(model.spec)
        z, zd = o.gap - x, -v
        f_inv = model.inverted_force(o)
        f_mod = model.orbit_force(x, v)
        for label, fo, style, c in (("implied by the measured orbit", f_inv, "-", _MEAS),
                                    ("model force law", f_mod, "--", col)):
            fg = force_vs_gap(z, zd, fo, n_bins=150)
            a.plot(fg["gap"] * L, fg["approach"] * Fn, style, color=c, lw=1.1,
                   label=f"{label}, approach")
            a.plot(fg["gap"] * L, fg["retract"] * Fn, style, color=c, lw=1.1, alpha=0.55,
                   label=f"{label}, retraction")
        a.axhline(0, color="k", lw=0.5)
        a.set_xlim(min(z) * L, min(max(z) * L, min(z) * L + 0.45 * (max(z) - min(z)) * L))
        a.set_title(title, fontsize=9)
        a.set_xlabel("tip-sample gap z [nm]")
    ax[0, 0].set_ylabel("tip-sample force [nN] (> 0 repulsive)")
    ax[0, 0].legend(fontsize=6)
    return _save(fig, _path(path))


def plot_energy(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Energy into the sample per cycle [eV]: measured balance, baseline, extended."""
    ev = dg.calibrated_.scales.energy / 1.602176634e-19
    e = dg.energy_
    fig, ax = _fig(5.5, 3.8, 1, 1)
    a = ax[0, 0]
    names = ["measured\n(drive - damping)", "baseline", f"extended\n({dg.cause_})"]
    vals = [e["measured"] * ev, e["baseline"] * ev, e["extended"] * ev]
    a.bar(names, vals, color=[_MEAS, _BASE, _EXT])
    for i, v in enumerate(vals):
        a.text(i, v, f"{v:.3g}", ha="center", va="bottom", fontsize=8)
    a.axhline(0, color="k", lw=0.5)
    a.set_ylabel("energy dissipated per cycle [eV]")
    return _save(fig, _path(path))


def plot_candidates(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Evidence and held-out gain of every tested cause (significant ones filled)."""
    cands = dg.candidates_
    names = [c.cause.replace("_", "\n") for c in cands]
    fig, ax = _fig(11, 4.0)
    a, b = ax[0, 0], ax[0, 1]
    x = np.arange(len(cands))
    d = np.array([max(c.delta_chi2, 1e-2) for c in cands])
    thr = np.array([c.threshold for c in cands])
    cols = [_EXT if c.cause == dg.cause_ else (_BASE if c.significant else "0.75")
            for c in cands]
    a.bar(x, d, color=cols)
    a.scatter(x, thr, marker="_", s=400, color="k", label="null threshold")
    a.set_yscale("log")
    a.set_xticks(x, names, fontsize=7)
    a.set_ylabel("chi2 drop over the baseline")
    a.legend(fontsize=7)
    g = np.array([c.gain if math.isfinite(c.gain) else -1.0 for c in cands])
    b.bar(x, np.clip(g, -1, 1), color=cols)
    b.axhline(dg.calibration_.min_gain, color="k", lw=0.7, ls="--", label="min gain")
    b.set_xticks(x, names, fontsize=7)
    b.set_ylabel("held-out gain 1 - NRMSE(ext)/NRMSE(base) (clipped to [-1, 1])")
    b.legend(fontsize=7)
    return _save(fig, _path(path))


def plot_all(dg: Any, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
    """Every figure into ``out_dir``; returns name -> path."""
    out = Path(out_dir)
    return {"residual": plot_residual(dg, out / "residual.png"),
            "orbit": plot_orbit(dg, out / "orbit.png"),
            "spectrum": plot_spectrum(dg, out / "spectrum.png"),
            "force_gap": plot_force_gap(dg, out / "force_gap.png"),
            "energy": plot_energy(dg, out / "energy.png"),
            "candidates": plot_candidates(dg, out / "candidates.png")}
