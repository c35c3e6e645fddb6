"""Figures of a lock-in curve diagnosis (matplotlib, Agg canvas, PNGs written atomically).

`plot_curve_fit`
    Measured amplitude and phase against the rest gap (approach and retraction) with the
    baseline and extended models' predictions and their residuals (what each model gets
    wrong; the retraction is held out).
`plot_curve_force`
    The fitted conservative force laws against the gap (baseline and extended).
`plot_curve_dissipation`
    Energy dissipated per cycle from amplitude and phase (Cleveland/Anczykowski), measured
    and as each model predicts it.
`plot_parameter_spread`
    Histograms of the fitted parameters across the curves of a folder (values not
    identified by their curve left out and counted).
`curve_figures`
    All three (the figure writer of ``scripts/analyze_curves.py``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from afmlearn.curves import CurveDiagnoser
from afmlearn.curves.dissipation import dissipated_energy
from afmlearn.curves.hypotheses import BASELINE, EXTENSIONS
from afmlearn.plots.trace import _save
from afmlearn.preprocess.phase import wrap_angle

__all__ = ["curve_residuals", "plot_curve_fit", "plot_curve_force", "plot_curve_dissipation",
           "curve_figures", "plot_parameter_spread", "spread_table"]



def _fits(diag: CurveDiagnoser) -> dict:
    """The fits drawn: the baseline, and the named cause's extension when one is named."""
    fits = {"baseline": diag.baseline_}
    if diag.cause_ != "none":
        fits[f"extended ({diag.cause_})"] = diag.extended_
    return fits


def curve_residuals(diag: CurveDiagnoser, preds: dict | None = None
                    ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Data minus model of each drawn fit (``"baseline"``, ``"extended (<cause>)"``).

    Parameters
    ----------
    diag : CurveDiagnoser
        Fitted.
    preds : dict, optional
        Precomputed ``label -> (amplitude / free amplitude, lag [rad])`` of the fits.

    Returns
    -------
    dict
        ``label -> (amplitude residual [% of the free amplitude], phase residual [deg],
        wrapped to (-180, 180])``, arrays of shape (m,) over the whole curve.
    """
    c = diag.curve_
    if preds is None:
        preds = {label: f.predict(c) for label, f in _fits(diag).items()}
    return {label: ((c.amplitude - a) * 100.0, np.degrees(wrap_angle(c.phase - p)))
            for label, (a, p) in preds.items()}


def plot_curve_fit(diag: CurveDiagnoser, path: str | os.PathLike[str]) -> Path:
    """Amplitude [nm] and phase [deg] against the rest gap [nm], data and models, and the
    residuals (data - model) that show what each model gets wrong.

    The x axis is the rest gap of the named model (piezo position minus its fitted surface
    position, plus drift; < 0: the rest position is pressed into the sample), symlog (linear
    within 0.2 free amplitudes of the surface). Approach points are fitted, retraction points
    held out. Rows: amplitude, amplitude residual [% of the free amplitude]
    (:func:`curve_residuals`), phase lag, phase residual [deg].
    """
    c = diag.curve_
    nm = c.length_m * 1e9
    named = diag.cause_ != "none"
    preds = {label: f.predict(c) for label, f in _fits(diag).items()}
    res = curve_residuals(diag, preds)
    x = diag.extended_.gap(c) * nm
    fig = Figure(figsize=(7.5, 8.5))
    ax_a, ax_ra, ax_p, ax_rp = fig.subplots(
        4, 1, sharex=True, gridspec_kw={"height_ratios": (3, 2, 3, 2)})
    seg_style = {0: ("approach (fitted)", "#1f77b4"), 1: ("retraction (held out)", "#ff7f0e")}
    for seg, (name, colour) in seg_style.items():
        m = c.segment == seg
        ax_a.plot(x[m], c.amplitude[m] * nm, ".", ms=2, color=colour, label=name)
        ax_p.plot(x[m], np.degrees(c.phase[m]), ".", ms=2, color=colour)
    # residuals: colour per model and branch (darker: retraction)
    res_colour = {("baseline", 0): "0.55", ("baseline", 1): "k",
                  ("extended", 0): "#f4a582", ("extended", 1): "#b2182b"}
    for (label, (a, p)), style in zip(preds.items(), ("k-", "r--"), strict=False):
        kind = label.split(" ")[0]
        ra, rp = res[label]
        for seg in (0, 1):
            m = c.segment == seg
            ax_a.plot(x[m], a[m] * nm, style, lw=1, label=label if seg == 0 else None)
            ax_p.plot(x[m], np.degrees(p[m]), style, lw=1)
            branch = "approach" if seg == 0 else "retraction"
            ax_ra.plot(x[m], ra[m], "-", lw=0.7, color=res_colour[kind, seg],
                       label=f"{kind}, {branch}")
            ax_rp.plot(x[m], rp[m], "-", lw=0.7, color=res_colour[kind, seg])
    for ax in (ax_ra, ax_rp):
        ax.axhline(0.0, color="0.7", lw=0.5)
    # log-like gap axis: the approach's last free amplitude (where the tip meets the surface)
    # gets as much room as the micron of free flight before it
    ax_rp.set_xscale("symlog", linthresh=max(1.0, 0.2 * nm))
    ax_a.set_ylabel("amplitude [nm]")
    ax_ra.set_ylabel("data - model\n[% of free amp.]")
    ax_p.set_ylabel("phase lag [deg]")
    ax_rp.set_ylabel("data - model\n[deg]")
    ax_rp.set_xlim(float(np.min(x)), float(np.max(x)))
    ax_rp.set_xlabel("rest gap [nm] (piezo - surface fitted by the named model; < 0 pressed; "
                     "symlog)")
    ax_a.legend(fontsize=7)
    ax_ra.legend(fontsize=6, ncol=2)
    b_held = diag.baseline_heldout_
    title = (f"{c.length_m * 1e9:.0f} nm free amplitude; cause: {diag.cause_}"
             + (f" (confidence {diag.confidence_:.2f}); held-out NRMSE {b_held:.4f} -> "
                f"{b_held * (1.0 - diag.gain_):.4f}, gain {diag.gain_:.3f}" if named
                else f"; held-out NRMSE {b_held:.4f}"))
    ax_a.set_title(title, fontsize=8)
    fig.tight_layout()
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
    """Energy dissipated per cycle [eV] against the rest gap [nm] (symlog, as
    :func:`plot_curve_fit`): measured (dots) and the same formula applied to each model's
    predicted amplitude and phase (lines: a conservative baseline dissipates ~0, up to the
    ramp's transients and the lock-in filter)."""
    c = diag.curve_
    ev = c.energy_unit_j / 1.602176634e-19
    w = diag.extended_.values_["omega"]
    x = diag.extended_.gap(c) * c.length_m * 1e9
    e = diag.dissipation() / 1.602176634e-19
    fig = Figure(figsize=(6.5, 4.2))
    ax = fig.subplots()
    for seg, name in ((0, "approach (data)"), (1, "retraction (data)")):
        m = c.segment == seg
        ax.plot(x[m], e[m], ".", ms=2, label=name)
    for (label, fit), style in zip(_fits(diag).items(), ("k-", "r--"), strict=False):
        a, p = fit.predict(c)
        em = dissipated_energy(a, p, free_amplitude=1.0, free_phase=c.free_phase,
                               quality_factor=c.quality_factor, omega=w) * ev
        for seg in (0, 1):
            m = c.segment == seg
            ax.plot(x[m], em[m], style, lw=1 if seg == 0 else 0.6,
                    label=f"{label}" if seg == 0 else None)
    ax.axhline(0.0, color="0.7", lw=0.5)
    ax.set_xscale("symlog", linthresh=max(1.0, 0.2 * c.length_m * 1e9))
    ax.set_xlim(float(np.min(x)), float(np.max(x)))
    ax.set_xlabel("rest gap [nm] (as the fit figure; symlog)")
    ax.set_ylabel("dissipated energy per cycle [eV]")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, Path(path))


def curve_figures(diag: CurveDiagnoser, out_dir: Path) -> list[Path]:
    """The three figures into ``out_dir``."""
    out = Path(out_dir)
    return [plot_curve_fit(diag, out / "curve_fit.png"),
            plot_curve_force(diag, out / "curve_force.png"),
            plot_curve_dissipation(diag, out / "curve_dissipation.png")]


#: (panel label, law field, hypothesis) of the fitted parameters shown by plot_parameter_spread
_SPREAD = (("adhesion, named model [nN]", "vdw", None),
           ("contact stiffness, baseline [nN/nm^1.5]", "stiffness", None),
           ("long-range damping [N s/m]", "damping", "long_range_damping"),
           ("damping decay length [nm]", "decay_length", "long_range_damping"),
           ("far-field damping [N s/m]", "far_damping", "long_range_damping"),
           ("far-field decay length [nm]", "far_decay_length", "long_range_damping"),
           ("free-amplitude scale (drive's / ramp start's)", "free_scale", "long_range_damping"),
           ("adhesion neck length [nm]", "neck", "adhesion_hysteresis"),
           ("viscoelastic coefficient [N s/m^1.5]", "visco", "viscoelastic"))


def _parameter_flag(field: str, value: float, length_m: float | None = None) -> str | None:
    """``"bound"`` when a fitted law parameter sits at its bound (within 2 % in log),
    ``"start"`` when it never left a starting value: an extension's start or a start-grid
    value (a number of at most two significant digits, which a least-squares step does not
    land on), else None. Parameters given in metres (the far-field decay) are compared in
    units of ``length_m`` [m] (the curve's free amplitude; None: not compared)."""
    for hyp in (BASELINE, *EXTENSIONS):
        for p in hyp.parameters:
            if p.field != field:
                continue
            if p.si_length:
                if length_m is None:
                    continue
                p = p.in_units(length_m)
            if p.log and value > 0 and min(abs(math.log(value / p.low)),
                                           abs(math.log(value / p.high))) < 0.02:
                return "bound"
            if hyp is not BASELINE and any(abs(value - s) <= 1e-9 * abs(s)
                                           for s in (p.init, *p.alternatives)):
                return "start"
    if value > 0:
        m = 100.0 * value / 10.0 ** math.floor(math.log10(value))
        if abs(m - round(m)) < 1e-6 and round(m) % 10 == 0:
            return "start"
    return None


def _si_parameters(row: dict) -> dict[str, tuple[float, str | None]]:
    """SI values of one row's fitted law, each with its flag (:func:`_parameter_flag`).

    The adhesion is the named model's, the contact stiffness the baseline's, the
    cause-specific parameters only on curves where that cause is named; dimensionless values
    are scaled by the row's k, f0 and free amplitude ``L``.
    """
    lu = row["free_amplitude_m"]
    k = row.get("spring_constant_n_per_m") or float("nan")
    w0 = 2 * np.pi * (row.get("resonance_frequency_hz") or float("nan"))
    base = row.get("baseline_parameters", row["parameters"])
    ext = row["parameters"]
    named = row["cause"] != "none"
    out: dict[str, tuple[float, str | None]] = {
        "free amplitude [nm]": (lu * 1e9, None),
        "held-out gain": (row["gain"] if named else np.nan, None)}
    # SI factor of each field: force unit k L; lengths L; rates per omega0 t
    scale = {"vdw": row.get("adhesion_force_n", np.nan) * 1e9 / ext.get("vdw", np.nan)
             if ext.get("vdw") else np.nan,
             "stiffness": k * lu * 1e9 / (lu * 1e9) ** 1.5,       # nN / nm^1.5
             "damping": k / w0,                                    # N s / m
             "decay_length": lu * 1e9, "neck": lu * 1e9,           # nm
             "far_damping": k / w0, "far_decay_length": lu * 1e9, "free_scale": 1.0,
             "visco": k / (w0 * math.sqrt(lu))}                    # N s / m^1.5
    for label, field, cause in _SPREAD:
        src = base if field == "stiffness" else ext
        if (cause is not None and row["cause"] != cause) or field not in src:
            continue
        v = float(src[field])
        flag = _parameter_flag(field, v, lu)
        if field == "vdw" and flag is None:
            # the adhesion is the force at contact: not identified when the named model's
            # contact stiffness is not (the model's tip never reached the contact)
            flag = _parameter_flag("stiffness", float(ext.get("stiffness", np.nan)))
        out[label] = (v * scale[field], flag)
    return out


def spread_table(rows: list[dict]) -> dict[str, tuple[dict[str, np.ndarray], dict[str, int]]]:
    """The values :func:`plot_parameter_spread` draws: ``label -> (group -> SI values of the
    identified fits, flag -> number of values left out)`` (flags of :func:`_parameter_flag`)."""
    groups = sorted({r.get("group", "") for r in rows})
    vals = [(r.get("group", ""), _si_parameters(r)) for r in rows]
    out = {}
    for key in {k for _, v in vals for k in v}:
        got = [(g, v[key]) for g, v in vals if key in v and np.isfinite(v[key][0])]
        data = {g: np.array([x for gg, (x, f) in got if gg == g and f is None], dtype=float)
                for g in groups}
        flags: dict[str, int] = {}
        for _, (_, f) in got:
            if f is not None:
                flags[f] = flags.get(f, 0) + 1
        out[key] = (data, flags)
    return out


def plot_parameter_spread(rows: list[dict], out_dir: Path) -> Path:
    """Histograms of fitted parameters across curves, one colour per group (``analyze_folder``
    rows; as Fig. 5 of the dissertation: the spread of one tip's parameters across curves).

    Cause-specific parameters are shown for the curves where that cause is named. Values at a
    bound of the fit or still at an extension's starting value are not identified by the
    curve: they are left out of the histogram and counted in the panel. Log-spaced bins for
    positive quantities spanning more than a decade. Writes ``parameter_spread.png``.
    """
    keys = ["free amplitude [nm]", "held-out gain", *(lab for lab, _, _ in _SPREAD)]
    table = spread_table(rows)
    groups = sorted({r.get("group", "") for r in rows})
    fig = Figure(figsize=(13.0, 9.5))
    axes = fig.subplots(3, 4).ravel()
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    for ax, key in zip(axes, keys, strict=False):
        ax.set_xlabel(key, fontsize=8)
        ax.set_ylabel("curves")
        data, flags = table.get(key, ({g: np.empty(0) for g in groups}, {}))
        note = ", ".join(f"{n} at {'a bound' if f == 'bound' else 'a start'}"
                         for f, n in sorted(flags.items()))
        if note:
            ax.set_title(f"not identified, left out: {note}", fontsize=7)
        allv = np.concatenate([d for d in data.values()])
        if allv.size == 0:
            ax.text(0.5, 0.5, "no curve", ha="center", va="center", transform=ax.transAxes)
            continue
        logx = bool(np.all(allv > 0) and allv.max() > 10 * allv.min())
        bins = (np.geomspace(allv.min(), allv.max() * (1 + 1e-9), 16) if logx
                else np.linspace(allv.min(), allv.max() + 1e-12, 16))
        ax.hist(list(data.values()), bins=bins, stacked=True,
                label=[f"{g} ({data[g].size})" for g in groups])
        if logx:
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=7)
    lines = []
    for g in groups:
        causes: dict[str, int] = {}
        for r in rows:
            if r.get("group", "") == g:
                causes[r["cause"]] = causes.get(r["cause"], 0) + 1
        lines.append(f"{g or 'all'}: " + ", ".join(f"{c} {n}" for c, n in
                                                  sorted(causes.items(), key=lambda t: -t[1])))
    fig.suptitle("\n".join(lines), fontsize=9)
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "parameter_spread.png")
