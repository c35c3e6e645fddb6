"""Figures of a force identification (matplotlib, Agg canvas, PNGs written atomically).

`plot_pareto`
    The Pareto front of the model selection: number of terms against the error objectives the
    knee was chosen on (``ForceIdentifier.objectives_``), drawn as 2-D projections; the front is
    highlighted, the knee (the choice) and the AICc choice (second opinion) are marked and
    labelled.
`plot_coefficients`
    Force-term coefficients of an identified model in SI units with their bagging bands
    (2.5--97.5 %), and the true coefficients as markers when known (training).
`plot_orbit`
    Measured against simulated deflection on the held-out span, and the phase portrait.
`plot_force`
    Time-resolved force with its band and force against gap on approach and retraction.
`plot_force_series`
    Joint fit of a set-point series: force against gap per set-point and the contact
    exponent's profile likelihood with its 95 % interval.
`identify_figures`
    All of the above for one identification (the figure writer of ``scripts/identify.py``).

Every function takes a fitted :class:`afmlearn.identify.identifier.ForceIdentifier` (or an
:class:`IdentifiedModel`), draws on an explicit Agg canvas (the caller's pyplot backend is never
touched), writes one PNG atomically and returns its path.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from afmlearn.identify.identifier import force_vs_gap
from afmlearn.identify.model import IdentifiedModel
from afmlearn.identify.selection import Candidate, pareto_front
from afmlearn.plots.trace import _save

__all__ = ["plot_pareto", "plot_coefficients", "plot_orbit", "plot_force", "objective_value",
           "heldout_simulation", "plot_force_series", "identify_figures", "training_figures"]

FloatArray = NDArray[np.float64]
_KNEE, _IC, _FRONT, _TRUE = "#d62728", "#1f77b4", "#ff7f0e", "#2ca02c"


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _path(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def objective_value(candidate: Candidate, name: str) -> float:
    """Value of one selection objective: a Candidate attribute or a key of ``scores``."""
    if name in candidate.scores:
        return float(candidate.scores[name])
    value = getattr(candidate, name, None)
    if value is None:
        raise ValueError(f"candidate has no objective {name!r} (attributes: cv_error, aicc, "
                         f"bic; scores: {sorted(candidate.scores)})")
    return float(value)


# ---------------------------------------------------------------------------- Pareto front
def plot_pareto(identifier: Any, path: str | os.PathLike[str]) -> Path:
    """Draw the 3-D Pareto front of the model selection.

    Parameters
    ----------
    identifier : ForceIdentifier
        Fitted; reads ``candidates_``, ``objectives_`` (names of the error objectives: Candidate
        attributes or ``scores`` keys), ``knee_index_`` and ``ic_index_``.
    path : str or os.PathLike
        PNG to write (parent folders are created).

    Returns
    -------
    pathlib.Path
        ``path``.

    Notes
    -----
    The front is the non-dominated set of (number of terms, objectives...), all minimised
    (:func:`afmlearn.identify.selection.pareto_front`). One panel per objective against the
    number of terms, and a last panel of the last two objectives coloured by the number of
    terms (with the force error on training data: terms x state error x force error).
    """
    cands: Sequence[Candidate] = identifier.candidates_
    names = tuple(identifier.objectives_)
    if len(names) == 1:
        names = (names[0], "aicc")
    n = np.array([c.n_terms for c in cands], float)
    errs = [np.array([objective_value(c, o) for c in cands]) for o in names]
    front = pareto_front(np.column_stack([n, *errs]))
    on = np.zeros(n.size, bool)
    on[front] = True
    ki, ii = int(identifier.knee_index_), int(identifier.ic_index_)
    # one panel per objective against the number of terms, and the last two objectives
    # against each other coloured by the number of terms (the 3-D front seen from above)
    views = [(n, e, "number of terms", o) for e, o in zip(errs, names, strict=True)]
    views.append((errs[-2], errs[-1], names[-2], names[-1]))
    fig = _new_figure(4.3 * len(views) + 0.8, 4.3)
    axes = fig.subplots(1, len(views))
    for k, (ax, (xs, ys, xl, yl)) in enumerate(zip(axes, views, strict=True)):
        last = k == len(views) - 1
        if last:
            sc = ax.scatter(xs, ys, c=n, cmap="viridis", s=22, zorder=2)
            ax.scatter(xs[on], ys[on], facecolors="none", edgecolors=_FRONT, s=70, zorder=3,
                       label="Pareto front")
            fig.colorbar(sc, ax=ax, label="number of terms")
        else:
            ax.plot(xs[~on], ys[~on], "o", color="0.65", ms=4, label="candidate", zorder=2)
            order = np.argsort(xs[on], kind="stable")
            ax.plot(xs[on][order], ys[on][order], "-o", color=_FRONT, ms=5, lw=1.2,
                    label="Pareto front", zorder=3)
        ax.plot(xs[ki], ys[ki], "*", color=_KNEE, ms=16, mec="k", zorder=4,
                label=f"knee (choice): {int(n[ki])} terms")
        ax.plot(xs[ii], ys[ii], "s", mfc="none", mec=_IC, mew=2, ms=12, zorder=5,
                label=f"AICc: {int(n[ii])} terms")
        ax.annotate("knee", (xs[ki], ys[ki]), textcoords="offset points", xytext=(6, 8),
                    color=_KNEE, fontsize="small")
        ax.annotate("AICc", (xs[ii], ys[ii]), textcoords="offset points", xytext=(6, -12),
                    color=_IC, fontsize="small")
        if np.all(ys[np.isfinite(ys)] > 0):
            ax.set_yscale("log")
        if last and np.all(xs[np.isfinite(xs)] > 0):
            ax.set_xscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize="small", loc="best")
    fig.suptitle(f"Model selection: Pareto front of (terms, {', '.join(names)}); "
                 f"{len(cands)} distinct supports, {int(on.sum())} on the front")
    return _save(fig, _path(path))


# ---------------------------------------------------------------------------- coefficients
def plot_coefficients(model: IdentifiedModel, truth: Mapping[str, float] | None,
                      path: str | os.PathLike[str]) -> Path:
    """Bar chart of the force-term coefficients (SI) with bagging bands and true values.

    Parameters
    ----------
    model : IdentifiedModel
        Its ``si_terms()`` give the bars; ``coefficient_bands`` (if any) the error bars,
        converted with the same SI factor per term.
    truth : mapping of str to float, optional
        True SI coefficients by term name (names as ``model.library.names``); terms absent
        from the model get their own bar position with a zero bar.
    path : str or os.PathLike
        PNG to write.

    Returns
    -------
    pathlib.Path
    """
    si = model.si_terms()
    names = [t["term"] for t in si]
    est = [t["coefficient"] for t in si]
    units = [t["unit"] for t in si]
    factor = np.array([s / c if c != 0 else 0.0
                       for s, c in zip(est, model.coefficients, strict=True)])
    lo = hi = None
    if model.coefficient_bands is not None:
        b = np.sort(model.coefficient_bands * factor, axis=0)
        lo, hi = b[0], b[1]
    truth = dict(truth or {})
    extra = [k for k in truth if k not in names]
    labels = names + extra
    values = np.array(est + [0.0] * len(extra))
    n_bars = max(len(labels), 1)
    fig = _new_figure(max(6.0, 1.1 * n_bars + 2.0), 4.8)
    ax = fig.subplots()
    pos = np.arange(len(labels))
    # coefficients of different terms have different units: draw |c| on a log axis with the
    # sign in the colour, so a 1e-20 and a 1e3 coefficient are both visible
    mag = np.abs(values)
    colors = ["#4c72b0" if v >= 0 else "#c44e52" for v in values]
    ax.bar(pos, np.where(mag > 0, mag, np.nan), color=colors, alpha=0.8, label="identified")
    if lo is not None and hi is not None:
        k = len(names)
        a, b = np.abs(lo), np.abs(hi)
        low, high = np.minimum(a, b), np.maximum(a, b)
        cross = (lo < 0) & (hi > 0)
        low = np.where(cross, np.minimum(low, mag[:k]) * 1e-3, low)
        ok = mag[:k] > 0
        ax.errorbar(pos[:k][ok], mag[:k][ok],
                    yerr=[np.clip(mag[:k] - low, 0, None)[ok],
                          np.clip(high - mag[:k], 0, None)[ok]],
                    fmt="none", ecolor="k", capsize=4, label="95 % bagging band")
    if truth:
        tv = np.array([abs(float(truth.get(k, 0.0))) for k in labels])
        ax.plot(pos, np.where(tv > 0, tv, np.nan), "D", color=_TRUE, mec="k", ms=8,
                label="truth", zorder=4)
    if np.any(mag > 0) or truth:
        ax.set_yscale("log")
    unit_of = dict(zip(names, units, strict=True))
    ticks = [f"{k}\n[{unit_of[k]}]" if k in unit_of else f"{k}\n(not identified)"
             for k in labels]
    ax.set_xticks(pos, ticks, rotation=30, ha="right", fontsize="small")
    ax.set_ylabel("|coefficient| (SI; blue > 0, red < 0)")
    ax.set_title(f"F_ts terms (a0 = {model.a0 * model.scales.length * 1e9:.3g} nm)")
    ax.grid(alpha=0.3, axis="y")
    if len(labels):
        ax.legend(fontsize="small")
    return _save(fig, _path(path))


# ---------------------------------------------------------------------------- orbit
def _view(identifier: Any, calibrated: Any) -> tuple[FloatArray, FloatArray]:
    """(tau (n,), rest gap (n,)) of the identified trace."""
    cal = calibrated if calibrated is not None else getattr(identifier, "calibrated_", None)
    if cal is None:
        raise ValueError("calibrated must be the afmlearn.preprocess.Calibrated view the "
                         "identifier was fitted on (this identifier has no calibrated_)")
    tau = np.asarray(cal.tau, float)
    gap = np.broadcast_to(np.asarray(cal.gap, float), tau.shape).astype(float)
    return tau, gap


def heldout_simulation(identifier: Any, tau: FloatArray, *, substeps: int = 4
                       ) -> tuple[FloatArray, FloatArray]:
    """The identified model simulated over the held-out span from the denoised state.

    Parameters
    ----------
    identifier : ForceIdentifier
        Fitted (``model_``, ``state_x_``, ``state_v_``, ``heldout_start_``).
    tau : ndarray, shape (n,)
        Dimensionless time of every sample.
    substeps : int
        RK4 steps per sample.

    Returns
    -------
    x, v : ndarray, shape (n - heldout_start_,)
        Simulated deflection and rate / L_ref from sample ``heldout_start_`` on.
    """
    i0 = int(identifier.heldout_start_)
    n_h = tau.size - i0
    dtau = float(tau[1] - tau[0])
    return identifier.model_.simulate(float(identifier.state_x_[i0]),
                                      float(identifier.state_v_[i0]), tau0=float(tau[i0]),
                                      dtau=dtau, n_samples=n_h, substeps=substeps)


def plot_orbit(identifier: Any, x_measured: FloatArray, path: str | os.PathLike[str], *,
               calibrated: Any = None, periods: float = 8.0) -> Path:
    """Measured against simulated deflection on the held-out span, and phase portraits.

    Parameters
    ----------
    identifier : ForceIdentifier
        Fitted.
    x_measured : ndarray, shape (n,)
        Measured deflection / L_ref (``Calibrated.x``).
    path : str or os.PathLike
        PNG to write.
    calibrated : Calibrated, optional
        The view the identifier was fitted on (``afmlearn.preprocess.calibrate``); default
        ``identifier.calibrated_``.
    periods : float
        Drive periods shown at the start of the held-out span.

    Returns
    -------
    pathlib.Path
    """
    tau, _ = _view(identifier, calibrated)
    model: IdentifiedModel = identifier.model_
    x_measured = np.asarray(x_measured, float)
    if x_measured.shape != tau.shape:
        raise ValueError(f"x_measured must have shape {tau.shape}, got {x_measured.shape}")
    i0 = int(identifier.heldout_start_)
    xs, vs = heldout_simulation(identifier, tau)
    ell_nm = model.scales.length * 1e9
    t_us = tau / model.scales.omega0 * 1e6
    spp = 2 * math.pi / (model.omega * float(tau[1] - tau[0]))
    m = min(int(round(periods * spp)), xs.size)
    fig = _new_figure(12.0, 4.6)
    ax1, ax2 = fig.subplots(1, 2, width_ratios=[2, 1])
    sl = slice(i0, i0 + m)
    ax1.plot(t_us[sl], x_measured[sl] * ell_nm, ".", ms=2, color="0.45", label="measured")
    ax1.plot(t_us[sl], identifier.state_x_[sl] * ell_nm, "-", lw=0.8, color=_TRUE,
             label="denoised")
    ax1.plot(t_us[sl], xs[:m] * ell_nm, "-", lw=1.2, color=_KNEE, label="identified model")
    err = identifier.summary_.get("state_accuracy_heldout")
    ax1.set_title("Held-out deflection" + (f" (state accuracy {err:.2%})" if err is not None
                                           else ""))
    ax1.set_xlabel("time [µs]")
    ax1.set_ylabel("deflection [nm]")
    ax1.legend(fontsize="small", loc="upper right")
    last = slice(max(xs.size - int(round(2 * spp)), 0), xs.size)
    ax2.plot(identifier.state_x_[i0:][last] * ell_nm, identifier.state_v_[i0:][last] * ell_nm,
             "-", color=_TRUE, lw=1.2, label="denoised measurement")
    ax2.plot(xs[last] * ell_nm, vs[last] * ell_nm, "--", color=_KNEE, lw=1.2,
             label="identified model")
    ax2.axvline(model.gap * ell_nm - model.a0 * ell_nm, color="0.3", ls=":", lw=1,
                label="contact onset (x = gap - a0)")
    ax2.set_xlabel("deflection [nm]")
    ax2.set_ylabel("dx/dτ [nm]")
    ax2.set_title("Phase portrait (last 2 periods)")
    ax2.legend(fontsize="small")
    return _save(fig, _path(path))


# ---------------------------------------------------------------------------- force
def plot_force(identifier: Any, path: str | os.PathLike[str], true_force: FloatArray | None = None,
               *, calibrated: Any = None, periods: float = 4.0) -> Path:
    """Time-resolved force with its 95 % band, and force against gap (approach / retraction).

    Parameters
    ----------
    identifier : ForceIdentifier
        Fitted (``force_``, ``force_lo_``, ``force_hi_``, ``state_x_``, ``state_v_``).
    path : str or os.PathLike
        PNG to write.
    true_force : ndarray, shape (n,), optional
        True ``F_ts`` / (k L_ref) (training on simulations).
    calibrated : Calibrated, optional
        The view the identifier was fitted on; default ``identifier.calibrated_``.
    periods : float
        Drive periods shown in the time panel (the last ones).

    Returns
    -------
    pathlib.Path
    """
    tau, gap = _view(identifier, calibrated)
    model: IdentifiedModel = identifier.model_
    sc = model.scales
    f_nn = sc.force * 1e9
    ell_nm = sc.length * 1e9
    f = np.asarray(identifier.force_, float)
    lo, hi = np.asarray(identifier.force_lo_, float), np.asarray(identifier.force_hi_, float)
    fitted, label, band = None, "identified", "95 % band (bagging)"
    fixed = getattr(identifier, "fixed_exponent_", None)
    if fixed is not None and fixed.force is not None:
        # the exponent is not identifiable: the quoted law (re-fitted at the fixed exponent)
        # with its band, the fitted law as a thin secondary line
        fitted, f = f, np.asarray(fixed.force["force"], float)
        lo, hi = np.asarray(fixed.force["lo"], float), np.asarray(fixed.force["hi"], float)
        label = f"quoted law (exponent fixed at {fixed.exponent:g})"
        band = f"95 % band (bagging, exponent fixed at {fixed.exponent:g})"
    z = gap - identifier.state_x_
    zd = -np.asarray(identifier.state_v_, float)
    t_us = tau / sc.omega0 * 1e6
    spp = 2 * math.pi / (model.omega * float(tau[1] - tau[0]))
    sl = slice(max(tau.size - int(round(periods * spp)), 0), tau.size)
    fig = _new_figure(12.0, 4.6)
    ax1, ax2 = fig.subplots(1, 2)
    if np.any(np.isfinite(lo[sl])):
        ax1.fill_between(t_us[sl], lo[sl] * f_nn, hi[sl] * f_nn, color=_KNEE, alpha=0.25,
                         lw=0, label=band)
    ax1.plot(t_us[sl], f[sl] * f_nn, color=_KNEE, lw=1.1, label=label)
    if fitted is not None:
        ax1.plot(t_us[sl], fitted[sl] * f_nn, ":", color="0.45", lw=0.8,
                 label="fitted law (exponent not identified)")
    if true_force is not None:
        ax1.plot(t_us[sl], np.asarray(true_force)[sl] * f_nn, "--", color="k", lw=1,
                 label="true")
    ax1.axhline(0, color="0.6", lw=0.6)
    ax1.set_xlabel("time [µs]")
    ax1.set_ylabel("F_ts [nN] (> 0 repulsive)")
    ax1.set_title("Time-resolved tip-sample force")
    ax1.legend(fontsize="small")
    ok = np.isfinite(f)
    curves = force_vs_gap(z[ok], zd[ok], f[ok], n_bins=150)
    g = curves["gap"] * ell_nm
    ax2.plot(g, curves["approach"] * f_nn, "-", color=_IC, label="approach (z' < 0)")
    ax2.plot(g, curves["retract"] * f_nn, "-", color=_FRONT, label="retraction (z' > 0)")
    if true_force is not None:
        tc = force_vs_gap(z[ok], zd[ok], np.asarray(true_force, float)[ok], n_bins=150)
        ax2.plot(g, tc["approach"] * f_nn, ":", color="k", lw=1, label="true approach")
        ax2.plot(g, tc["retract"] * f_nn, "--", color="0.4", lw=1, label="true retraction")
    ax2.axvline(model.a0 * ell_nm, color="0.3", ls=":", lw=1, label="a0")
    ax2.axhline(0, color="0.6", lw=0.6)
    ax2.set_xlabel("gap z [nm]")
    ax2.set_ylabel("F_ts [nN]")
    ax2.set_title("Force vs gap")
    ax2.legend(fontsize="small")
    return _save(fig, _path(path))


# ---------------------------------------------------------------------------- joint fits
def plot_force_series(identifier: Any, path: str | os.PathLike[str]) -> Path:
    """Force against gap of every set-point of a joint fit, and the exponent's profile.

    Parameters
    ----------
    identifier : ForceIdentifier
        Fitted on an experiment of several observations (``joint_``, ``force_`` (n_obs, n),
        ``state_x_``, ``exponent_profile_``).
    path : str or os.PathLike
        PNG to write.

    Returns
    -------
    pathlib.Path
    """
    res = identifier.joint_
    model: IdentifiedModel = identifier.model_
    sc = model.scales
    f_nn, ell_nm = sc.force * 1e9, sc.length * 1e9
    fig = _new_figure(12.0, 4.6)
    ax1, ax2 = fig.subplots(1, 2)
    n_obs = res.problem.n_obs
    for i, o in enumerate(res.problem.observations):
        z = o.gap + res.problem.offsets[i] - np.asarray(identifier.state_x_[i], float)
        zd = -np.asarray(identifier.state_v_[i], float)
        f = np.asarray(identifier.force_[i], float)
        fixed = getattr(identifier, "fixed_exponent_", None)
        if fixed is not None and fixed.force is not None:  # the quoted law at the fixed p
            f = np.asarray(fixed.force["force"][i], float)
        cur = force_vs_gap(z, zd, f, n_bins=120)
        colour = (i / max(n_obs - 1, 1), 0.3, 1 - i / max(n_obs - 1, 1))
        ax1.plot(cur["gap"] * ell_nm, cur["approach"] * f_nn, "-", color=colour, lw=1,
                 label=f"rest gap {o.gap * ell_nm:.2f} nm")
    fixed = getattr(identifier, "fixed_exponent_", None)
    quoted = fixed.model if fixed is not None and fixed.force is not None else model
    ax1.axvline(quoted.a0 * ell_nm, color="0.3", ls=":", lw=1, label="a0")
    ax1.axhline(0, color="0.6", lw=0.6)
    ax1.set_xlabel("gap z [nm]")
    ax1.set_ylabel("F_ts [nN] (> 0 repulsive), approach")
    ax1.set_title(f"One law, {n_obs} set-points" + (
        "" if quoted is model else f" (exponent fixed at {fixed.exponent:g})"))
    ax1.legend(fontsize="x-small")
    prof = identifier.exponent_profile_
    if prof is not None:
        ex = res.exponent
        lr = ex["n_rows"] * np.log(prof[:, 1] / np.nanmin(prof[:, 1]))
        ax2.plot(prof[:, 0], lr, "o-", ms=3, color=_KNEE)
        ax2.axhline(3.841, color="0.4", ls="--", lw=1, label="95 % (3.84)")
        lo, hi = ex["interval"]
        ax2.axvspan(lo, hi, color=_KNEE, alpha=0.15, label=f"interval {lo:.2f}-{hi:.2f}")
        ax2.set_ylim(0, max(20.0, 3.841 * 3))
        ax2.set_xlabel("contact exponent p")
        ax2.set_ylabel("likelihood ratio n log(RSS / RSS_min)")
        ax2.set_title("Exponent profile (a0, coefficients, offsets re-fitted)")
        ax2.legend(fontsize="small")
    else:
        ax2.text(0.5, 0.5, "no contact term: no exponent profile", ha="center",
                 transform=ax2.transAxes)
    return _save(fig, _path(path))


def identify_figures(identifier: Any, calibrated: Any, out_dir: str | os.PathLike[str]
                     ) -> dict[str, str]:
    """Every figure of an identification into ``out_dir``; ``{name: path}``.

    The writer :func:`afmlearn.identify.infer.identify_trace` takes as ``figures`` (called
    from ``scripts/identify.py``; the analysis never imports the plots).
    """
    out = Path(out_dir)
    files = {"pareto": str(plot_pareto(identifier, out / "pareto.png")),
             "coefficients": str(plot_coefficients(identifier.model_, None,
                                                   out / "coefficients.png"))}
    if getattr(identifier, "joint_", None) is not None and np.ndim(identifier.force_) == 2:
        files["force_figure"] = str(plot_force_series(identifier, out / "force.png"))
        return files
    files["orbit"] = str(plot_orbit(identifier, calibrated.x, out / "orbit.png",
                                    calibrated=calibrated))
    files["force_figure"] = str(plot_force(identifier, out / "force.png",
                                           calibrated=calibrated))
    return files


def training_figures(identifier: Any, calibrated: Any, folder: str | os.PathLike[str], *,
                     truth_si: Mapping[str, float] | None = None,
                     true_force: FloatArray | None = None) -> dict[str, str]:
    """Figures of one training run (simulation with its truth), ``{name: path}``."""
    out = Path(folder)
    return {
        "pareto": str(plot_pareto(identifier, out / "pareto.png")),
        "coefficients": str(plot_coefficients(identifier.model_, truth_si,
                                              out / "coefficients.png")),
        "orbit": str(plot_orbit(identifier, calibrated.x, out / "orbit.png",
                                calibrated=calibrated)),
        "force_figure": str(plot_force(identifier, out / "force.png", true_force,
                                       calibrated=calibrated)),
    }
