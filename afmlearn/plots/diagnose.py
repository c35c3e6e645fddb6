"""Figures of a diagnosis: what the baseline gets wrong, beside the extended model.

Every ``plot_*`` function takes a fitted :class:`afmlearn.diagnose.Diagnoser`, draws the
baseline (left) and the extended model (right) on one Agg figure, writes one PNG atomically
and returns its path. Units are SI at the edge: nm, nN, eV; time in drive periods. What a
panel draws is computed by a ``*_data`` helper that returns the arrays (tested against the
truth on synthetic data): a figure shows only what the data determine.

`plot_residual`
    Held-out deflection (raw, denoised) against each model's steady orbit, and the residual.
`plot_orbit`
    Phase portraits (deflection, velocity) of measurement and model.
`plot_spectrum` (:func:`spectrum_data`)
    COHERENT spectrum: the harmonics of the drive fitted over every period of the held-out
    record (period-averaged, so the noise on each drops as 1 / sqrt(samples)), with their
    noise level, each model's harmonics, and what is left between the harmonics (a
    second frequency shows there).
`plot_force_gap` (:func:`force_gap_data`)
    Force against gap on approach and retraction: each model's force law along the measured
    orbit, and the force the measured orbit implies under the model's lever, inverted from
    the harmonics that stand above the noise, drawn only where its uncertainty (noise band
    plus the truncation error of the missing harmonics) is below a tolerance.
`plot_setpoints` (:func:`setpoint_data`)
    Per set-point (one point per observation): held-out NRMSE of both models, first-harmonic
    amplitude and mean deflection (= -mean force / k) measured with their 2 sigma error bars
    against each model's prediction.
`plot_setpoint_residuals`
    One small panel per set-point: held-out residual of the baseline and of the extension.
`plot_energy`
    Energy into the sample per cycle: measured (drive minus lever damping), baseline, extended.
`plot_candidates`
    Evidence (chi-square drop vs its null threshold) and held-out gain of every cause.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from types import SimpleNamespace
from typing import Any, final

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from afmlearn.diagnose.balance import harmonics, synthesize
from afmlearn.plots.trace import _save
from afmlearn.preprocess import fit_harmonics

__all__ = ["plot_residual", "plot_orbit", "plot_spectrum", "plot_force_gap", "plot_energy",
           "plot_candidates", "plot_setpoints", "plot_setpoint_residuals", "plot_all",
           "spectrum_data", "spectrum_panel_data", "force_gap_data", "force_gap_panel_data",
           "setpoint_data", "observations"]

FloatArray = NDArray[np.float64]

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


def observations(dg: Any) -> list[Any]:
    """The per-observation results of a fitted Diagnoser (one element for a single orbit).

    Each has ``orbit``, ``heldout``, ``baseline``, ``extended``, ``baseline_nrmse``,
    ``extended_nrmse`` and ``gap_m``. A Diagnoser without ``observations_`` (one orbit) is
    viewed through its representative-observation attributes.
    """
    obs = getattr(dg, "observations_", None)
    if obs:
        return list(obs)
    return [SimpleNamespace(orbit=dg.orbit_, heldout=dg.heldout_, baseline=dg.baseline_,
                            extended=dg.extended_, baseline_nrmse=dg.baseline_nrmse_,
                            extended_nrmse=dg.extended_nrmse_,
                            gap_m=dg.orbit_.gap * dg.calibrated_.scales.length)]


def _models(dg: Any) -> list[tuple[str, str, Any, str]]:
    """(title, key of the held-out simulation, model, colour) for baseline and extension."""
    causes = [getattr(s, "cause", s) for s in (getattr(dg, "causes_", None) or [])]
    named = " + ".join(causes) if causes else dg.cause_
    ext = "extended: " + named if dg.cause_ != "none" else "extended: none (= baseline)"
    # the final extension (every cause named in turn) is simulated under "extended"; a
    # single-step diagnosis keys it by its cause
    key = "extended" if "extended" in dg.heldout_.simulated else dg.cause_
    return [("baseline (1 mode, VdW-DMT sphere)", "none", dg.baseline_, _BASE),
            (ext, key, dg.extended_, _EXT)]


def _sim(held: Any, key: str, rate: bool = False) -> FloatArray:
    """A model's simulated held-out deflection (or rate); the extension's key may be absent
    when the cause is none (then it is the baseline's)."""
    d = held.simulated_rate if rate else held.simulated
    return d[key] if key in d else d["none"]


def plot_residual(dg: Any, path: str | os.PathLike[str], *, periods: float = 4.0) -> Path:
    """Held-out deflection [nm] vs each model's steady orbit, with the residual below."""
    h = dg.heldout_
    L = dg.calibrated_.scales.length * 1e9
    per = 2 * math.pi / dg.calibrated_.omega
    n = min(h.tau.size, int(round(periods * dg.calibrated_.samples_per_period)))
    t = (h.tau[:n] - h.tau[0]) / per
    fig, ax = _fig(11, 5.5, 2, 2, sharex=True, sharey="row")
    for j, (title, key, _, col) in enumerate(_models(dg)):
        sim = _sim(h, key)[:n]
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
        a.plot(_sim(h, key)[:n] * L, _sim(h, key, rate=True)[:n] * L, "--", color=col,
               lw=1.2, label="model")
        a.axvline(dg.orbit_.gap * L - dg.baseline_.spec.a0 * L, color="0.7", lw=0.7, ls=":")
        a.set_title(title, fontsize=9)
        a.set_xlabel("deflection [nm] (dotted: contact onset of the baseline)")
    ax[0, 0].set_ylabel("velocity [nm per 1/omega0]")
    ax[0, 0].legend(fontsize=7)
    return _save(fig, _path(path))


# ---------------------------------------------------------------------- spectrum
def spectrum_data(tau: FloatArray, y: FloatArray, omega: float, *,
                  n_harmonics: int | None = None, false_rate: float = 0.05,
                  models: dict[str, Any] | None = None) -> dict[str, Any]:
    """Coherent (period-averaged) spectrum of a steady record, with its noise level.

    The harmonics of the drive are fitted by least squares over every sample (the same as
    averaging the record over its periods and transforming one period), so each harmonic's
    noise is ``sigma = noise_rms sqrt(2 / n_samples)``, not the raw per-bin floor of one
    window. A harmonic counts as detected above the amplitude that pure noise exceeds with
    probability ``false_rate / n_harmonics`` (Rayleigh; family-wise ``false_rate`` over all
    harmonics shown).

    Parameters
    ----------
    tau : ndarray, shape (n,)
        Dimensionless times ``omega0 t`` of the samples.
    y : ndarray, shape (n,)
        Measured deflection (any length unit; the outputs are in the same unit).
    omega : float
        Drive frequency / f0.
    n_harmonics : int, optional
        Harmonics fitted; default ``min(40, samples per period / 2 - 1)``.
    false_rate : float
        Family-wise chance that a pure-noise harmonic is drawn as detected, in (0, 1).
    models : dict, optional
        Noise-free model deflections: name -> array at ``tau``, or a tuple
        ``(tau_m, y_m)`` with its own times. Their harmonics are returned too.

    Returns
    -------
    dict
        ``harmonic`` (N,) int 1..N; ``amplitude`` (N,) measured ``|Y_n|``; ``sigma`` float,
        noise std of each real coefficient; ``noise_level`` float, the detection amplitude;
        ``detected`` (N,) bool; ``models`` dict name -> (N,) amplitudes;
        ``between_frequency`` (m,) [drive frequencies] and ``between_amplitude`` (m,):
        spectrum of what the harmonics leave (``y`` minus its coherent part over whole
        periods, rectangular window, same normalisation, so a second frequency shows at its
        own amplitude).
    """
    if not 0.0 < false_rate < 1.0:
        raise ValueError(f"false_rate must be in (0, 1), got {false_rate!r}")
    tau = np.asarray(tau, float)
    y = np.asarray(y, float)
    spp = 2 * math.pi / (omega * float(tau[1] - tau[0]))
    if n_harmonics is None:
        n_harmonics = int(min(40, max(math.floor(spp / 2) - 1, 1)))
    hf = fit_harmonics(tau, y, omega, n_harmonics=n_harmonics)
    amp = hf.amplitudes
    sigma = float(hf.noise_rms * math.sqrt(2.0 / hf.n_samples))
    level = math.sqrt(-2.0 * math.log(false_rate / n_harmonics)) * sigma
    m = int(math.floor(y.size / spp) * spp) or y.size
    r = (y - hf.evaluate(tau))[:m]
    between = np.abs(np.fft.rfft(r)) * 2.0 / m
    freq = np.fft.rfftfreq(m, d=1.0 / spp)
    out_models = {}
    for k, v in (models or {}).items():
        tm, ym = v if isinstance(v, tuple) else (tau, v)
        out_models[k] = fit_harmonics(np.asarray(tm, float), np.asarray(ym, float), omega,
                                      n_harmonics=n_harmonics).amplitudes
    keep = freq <= n_harmonics + 0.5
    return {"harmonic": np.arange(1, n_harmonics + 1), "amplitude": amp, "sigma": sigma,
            "noise_level": level, "detected": amp > level, "models": out_models,
            "between_frequency": freq[keep], "between_amplitude": between[keep]}


def spectrum_panel_data(dg: Any) -> dict[str, Any]:
    """The :func:`spectrum_data` that :func:`plot_spectrum` draws: the whole record of the
    representative observation (every period averages the noise), each model's steady orbit
    over its held-out span (noise-free); lengths / L_ref, models keyed "none" and the cause."""
    h = dg.heldout_
    cal = dg.calibrated_
    models = {key: (h.tau, _sim(h, key)) for _, key, _, _ in _models(dg)}
    return spectrum_data(cal.tau, cal.x, cal.omega, models=models)


def plot_spectrum(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Coherent amplitude spectra [nm] of the held-out record and of each model's orbit."""
    cal = dg.calibrated_
    L = cal.scales.length * 1e9
    d = spectrum_panel_data(dg)
    n = d["harmonic"]
    fig, ax = _fig(11, 4.5, sharey=True)
    floor = d["noise_level"] * L
    for j, (title, key, model, col) in enumerate(_models(dg)):
        a = ax[0, j]
        a.semilogy(d["between_frequency"], np.maximum(d["between_amplitude"] * L, 1e-9),
                   color="0.8", lw=0.5, label="measured minus its harmonics (non-coherent)")
        det = d["detected"]
        a.vlines(n[det], floor / 10, d["amplitude"][det] * L, color="k", lw=1.2)
        a.plot(n[det], d["amplitude"][det] * L, "o", color="k", ms=4,
               label="measured harmonic (coherent, above noise)")
        a.plot(n[~det], d["amplitude"][~det] * L, "o", mfc="none", color="0.5", ms=4,
               label="measured harmonic below the noise level")
        a.axhline(floor, color="k", ls=":", lw=0.8,
                  label="noise level (5 % false detections over all harmonics)")
        a.plot(n, np.maximum(d["models"][key] * L, 1e-9), "x", color=col, ms=5,
               label="model harmonic")
        if model.spec.extra_mode is not None:
            r = model.spec.extra_mode.mode_parameters()[0] / cal.omega
            a.axvline(r, color=col, ls=":", lw=1, label=f"mode 2 ({r:.2f} f_drive)")
        err = (getattr(dg, "spectral_error_", None) or {}).get(
            "baseline" if key == "none" else "extended", math.nan)
        a.set_title(f"{title}\nspectral error {err:.3g}; {int(det.sum())} of {n.size} "
                    f"harmonics above the noise (coherent)", fontsize=8)
        a.set_xlabel("frequency / drive frequency")
        a.set_ylim(bottom=floor / 10)
    ax[0, 0].set_ylabel("amplitude [nm]")
    ax[0, 0].legend(fontsize=6)
    return _save(fig, _path(path))


# ---------------------------------------------------------------------- force vs gap
@final
class _Harmonics:
    """Duck-types PeriodicOrbit for ``DiagnosisModel.inverted_force`` with given harmonics."""

    def __init__(self, orbit: Any, X: NDArray[np.complex128]) -> None:
        self.grid = orbit.grid
        self.quality_factor = orbit.quality_factor
        self._X = X

    def true_orbit(self, spec: Any) -> tuple[None, None, NDArray[np.complex128]]:
        return None, None, self._X


def force_gap_data(orbit: Any, model: Any, *, significance: float = 3.0,
                   tolerance: float = 0.1, scale: float | None = None) -> dict[str, Any]:
    """What the force-versus-gap panel draws for one model on one measured orbit.

    The lever equation inverted on the measured orbit weighs harmonic ``n`` by ``~n^2``, so
    harmonics at the noise make the implied force swing by many nN where the true force is
    zero. Here only harmonics ``0..n_keep`` enter, ``n_keep`` the highest one above
    ``significance`` sigma, with Lanczos factors against the truncation's ringing; the
    uncertainty of the result is the noise band (2 sigma, propagated exactly through the
    linear inversion) plus the truncation error (what dropping the harmonics above
    ``n_keep`` does to the model's own force along this orbit, maximal over a resolution
    cell). The inversion is *determined* where that uncertainty is below ``tolerance`` times
    ``scale`` (the force range that matters); elsewhere it is NaN (not drawn).

    Parameters
    ----------
    orbit : PeriodicOrbit
        Denoised measured orbit (grid of one drive period).
    model : DiagnosisModel
        The model whose lever (K, D, B, drive phase, second mode, detector) inverts it.
    significance : float
        Harmonic detection level in sigma of one real coefficient, > 0.
    tolerance : float
        Largest uncertainty drawn, as a share of ``scale``, > 0.
    scale : float, optional
        Force range [k L_ref] the tolerance refers to; default the model's own force range
        along the orbit (:func:`force_gap_panel_data` passes the baseline's to both models,
        so an extension with an extreme force law does not loosen it).

    Returns
    -------
    dict
        Arrays of shape (grid,) over one period (dimensionless: gaps / L_ref, forces
        / (k L_ref)): ``theta``, ``z`` (gap along the measured orbit), ``zdot``, ``model``
        (the model's force law there), ``inverted`` (NaN where not determined),
        ``inverted_all`` (the same, everywhere), ``band`` (half-width of the uncertainty),
        ``noise_band`` (2 sigma part), ``determined`` (bool); and ``n_keep`` (int),
        ``tolerance`` (absolute, float).
    """
    if not significance > 0 or not tolerance > 0:
        raise ValueError(f"significance and tolerance must be > 0, got {significance!r}, "
                         f"{tolerance!r}")
    x, v, X = orbit.true_orbit(model.spec)
    n_h = X.size - 1
    sig = np.asarray(orbit.sigma_rows, float)
    s_re = sig[: n_h + 1]
    s_im = np.concatenate([[0.0], sig[n_h + 1:]])
    s = np.maximum(s_re, s_im)
    above = np.flatnonzero(np.abs(X[1:]) > significance * s[1:]) + 1
    n_keep = int(max(above.max() if above.size else 1, 1))
    Xk = X[: n_keep + 1]
    inv = model.inverted_force(_Harmonics(orbit, Xk))
    base = model.inverted_force(_Harmonics(orbit, np.zeros_like(Xk)))
    var = np.zeros(orbit.grid)
    for k in range(n_keep + 1):
        for unit, sk in ((1.0, s_re[k]), (1j, s_im[k])):
            if sk == 0.0:
                continue
            e = np.zeros_like(Xk)
            e[k] = unit
            var += (sk * (model.inverted_force(_Harmonics(orbit, e)) - base)) ** 2
    noise = 2.0 * np.sqrt(var)
    f_mod = model.orbit_force(x, v)
    n = np.arange(n_keep + 1)
    lp = synthesize(harmonics(f_mod, n_keep) * np.sinc(n / (n_keep + 1)), orbit.grid)
    cell = max(int(orbit.grid / (4 * (n_keep + 1))), 1)
    trunc = np.abs(f_mod - lp)
    padded = np.concatenate([trunc[-cell:], trunc, trunc[:cell]])
    trunc = np.max(np.lib.stride_tricks.sliding_window_view(padded, 2 * cell + 1), axis=1)
    band = noise + trunc
    ref = float(np.ptp(f_mod)) if scale is None else float(scale)
    tol = tolerance * ref if ref > 0 else float(np.max(noise))
    det = band <= tol
    return {"theta": orbit.theta, "z": orbit.gap - x, "zdot": -v, "model": f_mod,
            "inverted": np.where(det, inv, np.nan), "inverted_all": inv, "band": band,
            "noise_band": noise, "determined": det, "n_keep": n_keep, "tolerance": tol}


def _branches(z: FloatArray, zdot: FloatArray) -> list[tuple[str, NDArray[np.intp]]]:
    """Approach (z' < 0) and retraction: sample indices of each, sorted by gap."""
    out = []
    for name, m in (("approach", zdot < 0), ("retraction", zdot >= 0)):
        idx = np.flatnonzero(m)
        out.append((name, idx[np.argsort(z[idx])]))
    return out


def force_gap_panel_data(dg: Any, *, significance: float = 3.0, tolerance: float = 0.1
                         ) -> list[list[dict[str, Any]]]:
    """What :func:`plot_force_gap` draws: per model (baseline, extended), one
    :func:`force_gap_data` dict per observation (tolerance relative to the baseline's force
    range on that orbit)."""
    out: list[list[dict[str, Any]]] = [[], []]
    for ob in observations(dg):
        base = force_gap_data(ob.orbit, ob.baseline, significance=significance,
                              tolerance=tolerance)
        out[0].append(base)
        out[1].append(force_gap_data(ob.orbit, ob.extended, significance=significance,
                                     tolerance=tolerance, scale=float(np.ptp(base["model"]))))
    return out


def plot_force_gap(dg: Any, path: str | os.PathLike[str], *, significance: float = 3.0,
                   tolerance: float = 0.1) -> Path:
    """Force [nN] vs gap [nm] on approach and retraction, every set-point.

    Left the baseline, right the extension: its force law along each measured orbit, and
    the force the measured orbit implies under its lever where that is determined, with its
    uncertainty band (:func:`force_gap_data`).
    """
    sc = dg.calibrated_.scales
    L, Fn = sc.length * 1e9, sc.force * 1e9
    panels = force_gap_panel_data(dg, significance=significance, tolerance=tolerance)
    fig, ax = _fig(11, 4.8, sharey=True)
    for j, (title, _, _, col) in enumerate(_models(dg)):
        a = ax[0, j]
        zmin, zmax, n_det = math.inf, -math.inf, 0
        for i, d in enumerate(panels[j]):
            for name, idx in _branches(d["z"], d["zdot"]):
                ls = "-" if name == "approach" else "--"
                z = d["z"][idx] * L
                a.plot(z, d["model"][idx] * Fn, ls, color=col, lw=1.0, alpha=0.8,
                       label=f"model force law, {name}" if i == 0 else None)
                a.plot(z, d["inverted"][idx] * Fn, ls, color="k", lw=1.2,
                       label=f"implied by the measured orbit, {name}" if i == 0 else None)
                ok = d["determined"][idx]
                lo = np.where(ok, (d["inverted_all"] - d["band"])[idx], np.nan) * Fn
                hi = np.where(ok, (d["inverted_all"] + d["band"])[idx], np.nan) * Fn
                a.fill_between(z, lo, hi, color="0.6", alpha=0.25, lw=0,
                               label="its uncertainty" if i == 0 and name == "approach"
                               else None)
            n_det += bool(d["determined"].any())
            zmin, zmax = min(zmin, float(d["z"].min())), max(zmax, float(d["z"].max()))
        a.axhline(0, color="k", lw=0.5)
        a.set_xlim(zmin * L, min(zmax * L, zmin * L + 0.45 * (zmax - zmin) * L))
        top = max(d["n_keep"] for d in panels[j])
        note = (f"measured-orbit force drawn where determined ({n_det} of {len(panels[j])} "
                f"orbits; harmonics up to {top})" if n_det else
                f"measured-orbit force not determined at this noise (harmonics above "
                f"{significance:g} sigma: up to {top})")
        a.set_title(f"{title}\n{note}", fontsize=8)
        a.set_xlabel("tip-sample gap z [nm]")
    ax[0, 0].set_ylabel("tip-sample force [nN] (> 0 repulsive)")
    ax[0, 0].legend(fontsize=6)
    return _save(fig, _path(path))


# ---------------------------------------------------------------------- set-points
def setpoint_data(dg: Any) -> dict[str, Any]:
    """What :func:`plot_setpoints` draws, one entry per observation (set-point).

    Measured quantities come from each observation's held-out record (for a series: the
    whole record of a set-point the model was refitted without), each model's from its
    simulated steady orbit over the same span.

    Returns
    -------
    dict
        Arrays of shape (n_obs,): ``gap_m`` [m] (rest gap), ``nrmse`` dict "baseline" /
        "extended"; ``amplitude`` (first-harmonic amplitude / L_ref) and ``mean``
        (mean deflection / L_ref, i.e. ``-<F_ts> / (k L_ref)`` in steady state), each a dict
        with "measured", "sigma" (one standard deviation of the measured value),
        "baseline", "extended".
    """
    obs = observations(dg)
    keys = [k for _, k, _, _ in _models(dg)]
    out: dict[str, Any] = {"gap_m": np.array([float(ob.gap_m) for ob in obs]),
                           "nrmse": {"baseline": np.array([ob.baseline_nrmse for ob in obs]),
                                     "extended": np.array([ob.extended_nrmse for ob in obs])}}
    amp: dict[str, list[float]] = {k: [] for k in ("measured", "sigma", "baseline", "extended")}
    mean: dict[str, list[float]] = {k: [] for k in amp}
    omega = dg.calibrated_.omega
    for ob in obs:
        h = ob.heldout
        hf = fit_harmonics(h.tau, h.measured, omega, n_harmonics=min(ob.orbit.n_h, 20))
        Y = hf.complex_amplitudes
        amp["measured"].append(float(abs(Y[1])))
        amp["sigma"].append(float(hf.noise_rms * math.sqrt(2.0 / hf.n_samples)))
        mean["measured"].append(float(Y[0].real))
        mean["sigma"].append(float(hf.noise_rms / math.sqrt(hf.n_samples)))
        for name, key in zip(("baseline", "extended"), keys, strict=True):
            y = _sim(h, key)
            if np.all(np.isfinite(y)):
                Ym = fit_harmonics(h.tau, y, omega, n_harmonics=min(ob.orbit.n_h, 20)
                                   ).complex_amplitudes
                amp[name].append(float(abs(Ym[1])))
                mean[name].append(float(Ym[0].real))
            else:
                amp[name].append(math.nan)
                mean[name].append(math.nan)
    out["amplitude"] = {k: np.array(v) for k, v in amp.items()}
    out["mean"] = {k: np.array(v) for k, v in mean.items()}
    return out


def plot_setpoints(dg: Any, path: str | os.PathLike[str]) -> Path:
    """Per set-point: held-out NRMSE, amplitude [nm] and mean force [nN] against rest gap."""
    sc = dg.calibrated_.scales
    L, Fn = sc.length * 1e9, sc.force * 1e9
    d = setpoint_data(dg)
    g = d["gap_m"] * 1e9
    order = np.argsort(g)
    g = g[order]
    fig, ax = _fig(13, 4.0, 3, 1)
    a = ax[0, 0]
    for name, col in (("baseline", _BASE), ("extended", _EXT)):
        a.semilogy(g, d["nrmse"][name][order], "o-", color=col, ms=4, label=name)
    a.set_ylabel("held-out NRMSE (set-point not fitted)")
    a.legend(fontsize=7)
    for a, key, scale, ylabel in (
            (ax[0, 1], "amplitude", L, "first-harmonic amplitude [nm]"),
            (ax[0, 2], "mean", -Fn, "mean tip-sample force -k<x> [nN]")):
        m = d[key]
        a.errorbar(g, m["measured"][order] * scale, yerr=2 * m["sigma"][order] * abs(scale),
                   fmt="o", color="k", ms=4, capsize=2, label="measured (2 sigma)")
        for name, col in (("baseline", _BASE), ("extended", _EXT)):
            a.plot(g, m[name][order] * scale, "x--", color=col, ms=6, lw=0.8,
                   label=f"{name} prediction")
        a.set_ylabel(ylabel)
        a.legend(fontsize=7)
    for a in ax[0]:
        a.set_xlabel("rest gap [nm]")
    return _save(fig, _path(path))


def plot_setpoint_residuals(dg: Any, path: str | os.PathLike[str], *,
                            periods: float = 2.0) -> Path:
    """One panel per set-point: held-out residual [nm] (denoised measured minus model)."""
    obs = observations(dg)
    cal = dg.calibrated_
    L = cal.scales.length * 1e9
    per = 2 * math.pi / cal.omega
    ncols = min(4, len(obs))
    nrows = math.ceil(len(obs) / ncols)
    fig, ax = _fig(3.2 * ncols, 2.4 * nrows, ncols, nrows, sharex=True, sharey=True)
    order = np.argsort([float(ob.gap_m) for ob in obs])
    for k, i in enumerate(order):
        ob = obs[i]
        a = ax[k // ncols, k % ncols]
        h = ob.heldout
        n = min(h.tau.size, int(round(periods * cal.samples_per_period)))
        t = (h.tau[:n] - h.tau[0]) / per
        for (_, key, _, col), nr in zip(_models(dg), (ob.baseline_nrmse, ob.extended_nrmse),
                                        strict=True):
            a.plot(t, (h.reference[:n] - _sim(h, key)[:n]) * L, color=col, lw=0.9,
                   label=f"NRMSE {nr:.2g}")
        a.axhline(0, color="k", lw=0.5)
        a.set_title(f"rest gap {float(ob.gap_m) * 1e9:.2f} nm", fontsize=8)
        a.legend(fontsize=6)
    for k in range(len(obs), nrows * ncols):
        ax[k // ncols, k % ncols].set_visible(False)
    ax[0, 0].set_ylabel("measured - model [nm]")
    return _save(fig, _path(path))


# ---------------------------------------------------------------------- energy, evidence
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
    if not cands:
        for ax_ in (a, b):
            ax_.text(0.5, 0.5, "no cause tested", ha="center", va="center")
        return _save(fig, _path(path))
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
    """Every figure into ``out_dir``; returns name -> path (the per-set-point figures only
    for experiments of several observations)."""
    out = Path(out_dir)
    figs = {"residual": plot_residual(dg, out / "residual.png"),
            "orbit": plot_orbit(dg, out / "orbit.png"),
            "spectrum": plot_spectrum(dg, out / "spectrum.png"),
            "force_gap": plot_force_gap(dg, out / "force_gap.png"),
            "energy": plot_energy(dg, out / "energy.png"),
            "candidates": plot_candidates(dg, out / "candidates.png")}
    if len(observations(dg)) > 1:
        figs["setpoints"] = plot_setpoints(dg, out / "setpoints.png")
        figs["setpoint_residuals"] = plot_setpoint_residuals(dg, out / "setpoint_residuals.png")
    return figs
