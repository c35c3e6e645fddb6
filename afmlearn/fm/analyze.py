"""The whole analysis of one Δf(z, V) map: :func:`analyze_fm` (scripts/analyze_fm.py).

Steps (report.json keys in brackets):

1. model-free Kelvin parabola at each piezo position: CPD(z) [``kelvin``];
2. the fit window: the closest ``exclude_closest_m`` of piezo travel (repulsive contact, where
   the map's bias dependence is not a parabola of the electrostatic sphere) is left out of the
   main fits and reported separately [``window``, ``all_rows``];
3. held-out test on bias columns not fitted (every ``heldout_every``-th column): baseline law
   without electrostatics, the same law with the electrostatic terms at ``V_cpd = 0``, and the
   extended law with a fitted ``V_cpd`` [``baseline``, ``baseline_vcpd0``, ``extended``,
   ``gain``, ``cause``];
4. the extended law refitted on all columns, the profile interval of ``V_cpd`` (and the
   spread over fit windows, a row-block jackknife), the model's own CPD(z) and the residual
   structure (by distance; odd in the bias about ``V_cpd``: drift along the bias sweep or
   bias-dependent short-range forces) [``vcpd``, ``residual``];
5. all rows: one law refitted from scratch [``all_rows``], and staged: the window's
   electrostatics held and a bias-independent short-range law (vdW + DMT) fitted to what is
   left; what then remains in the contact rows is bias-dependent [``staged``].
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from afmlearn.fm.fit import FMFit, model_hz
from afmlearn.fm.kelvin import kelvin_parabolas
from afmlearn.fm.model import FMLaw
from afmlearn.io.instruments.fm_table import FMSpectroscopy, read_fm_spectroscopy
from afmlearn.io.jsonfile import jsonable, write_json
from afmlearn.metrics import nrmse

__all__ = ["analyze_fm", "equation", "heldout_split"]

log = logging.getLogger(__name__)


def heldout_split(n_bias: int, every: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``(fitted, held_out)`` column indices: every ``every``-th column (from 0) held out."""
    if every < 2:
        raise ValueError(f"heldout_every must be >= 2, got {every}")
    idx = np.arange(n_bias)
    return idx[idx % every != 0], idx[idx % every == 0]


def equation(law: FMLaw) -> str:
    """One line: the law in SI units."""
    text = (f"F = vdW sphere(H={law.hamaker_j:.3g} J, R={law.tip_radius_m * 1e9:.3g} nm)"
            f" + DMT(E*={law.modulus_pa:.3g} Pa)")
    if law.electrostatic:
        text += (f" - pi eps0 R_e^2 (V - {law.vcpd_v:.3f} V)^2 / (D (D + R_e)),"
                 f" R_e={law.es_radius_m * 1e9:.3g} nm, D = d + {law.es_setback_m * 1e9:.3g} nm;"
                 f" far gradient {law.far_gradient_n_per_m_v2:.3g} N/m/V^2"
                 f" (V - {law.far_v:.3f} V)^2")
    return text + f"; z_contact={law.z_contact_m * 1e9:.3f} nm, offset {law.offset_hz:.3g} Hz"


def _scores(fit: FMFit, spec: FMSpectroscopy) -> dict[str, float]:
    pred = fit.predict_hz(spec)
    true = spec.frequency_shift_hz
    return {"heldout_rms_hz": float(np.sqrt(np.mean((pred - true) ** 2))),
            "heldout_nrmse": nrmse(pred.ravel(), true.ravel())}


def _entry(fit: FMFit, spec_test: FMSpectroscopy) -> dict[str, Any]:
    return {"equation": equation(fit.law_), "law": fit.law_.to_dict(),
            "fit_rms_hz": fit.rms_hz_, **_scores(fit, spec_test)}


def _residual_structure(spec: FMSpectroscopy, law: FMLaw) -> dict[str, Any]:
    """Residual of ``law`` on ``spec``: :func:`_residual_parts` about the law's ``V_cpd``."""
    return _residual_parts(spec.frequency_shift_hz - model_hz(spec, law), spec.bias_v,
                           law.vcpd_v)


def _residual_parts(res: NDArray[np.float64], bias: NDArray[np.float64], vcpd: float
                    ) -> dict[str, Any]:
    """RMS of a residual (n_z, n_bias) [Hz], by row, and its parts even and odd in the bias
    about ``vcpd`` (each column paired with its mirror ``2 vcpd - V`` where one exists)."""
    row_rms = np.sqrt(np.mean(res**2, axis=1))
    mirror = 2.0 * vcpd - bias
    j = np.abs(bias[None, :] - mirror[:, None]).argmin(axis=1)
    ok = np.abs(bias[j] - mirror) <= 0.5 * np.min(np.abs(np.diff(np.sort(bias))))
    odd = 0.5 * (res[:, ok] - res[:, j[ok]])
    even = 0.5 * (res[:, ok] + res[:, j[ok]])
    return {"rms_hz": float(np.sqrt(np.mean(res**2))),
            "row_rms_hz": row_rms.tolist(),
            "odd_in_bias_rms_hz": float(np.sqrt(np.mean(odd**2))) if odd.size else None,
            "even_in_bias_rms_hz": float(np.sqrt(np.mean(even**2))) if even.size else None}


def _jackknife_vcpd(win: FMSpectroscopy, law: FMLaw, bounds: tuple[float, float],
                    n_blocks: int) -> dict[str, Any] | None:
    """Delete-a-block jackknife of ``V_cpd``: refit without each of ``n_blocks`` contiguous
    row blocks; standard error and a normal 95 % interval."""
    if n_blocks == 0:
        return None
    if n_blocks < 3 or win.shape[0] < 2 * n_blocks:
        raise ValueError(f"jackknife_blocks must be 0 or 3..{win.shape[0] // 2}, got {n_blocks}")
    blocks = np.array_split(np.arange(win.shape[0]), n_blocks)
    values = []
    for block in blocks:
        keep = np.setdiff1d(np.arange(win.shape[0]), block)
        values.append(FMFit(contact_bounds_m=bounds).fit(win.rows(keep), initial=law).law_.vcpd_v)
    v = np.asarray(values)
    se = math.sqrt((n_blocks - 1) / n_blocks * float(np.sum((v - v.mean()) ** 2)))
    return {"values_v": v.tolist(), "se_v": se,
            "interval_95_v": [law.vcpd_v - 1.96 * se, law.vcpd_v + 1.96 * se]}


def analyze_fm(data: str | os.PathLike[str] | FMSpectroscopy, out_dir: str | os.PathLike[str],
               *, exclude_closest_m: float = 3e-9, heldout_every: int = 4,
               reference_vcpd_v: float | None = None, profile_points: int = 13,
               window_variants_m: tuple[float, ...] = (), jackknife_blocks: int = 0,
               figures: Callable[[dict[str, Any], FMSpectroscopy, Path], list[Path]] | None = None,
               **calibration: Any) -> dict[str, Any]:
    """Analyse a Δf(z, V) map and write ``<out_dir>/report.json`` (+ figures).

    Parameters
    ----------
    data : path or FMSpectroscopy
        Folder / CSV for :func:`read_fm_spectroscopy`, or the map itself.
    out_dir : path
        Output folder (created).
    exclude_closest_m : float
        Piezo travel [m] from the closest position left out of the main fits (>= 0).
    heldout_every : int
        Every n-th bias column is held out of the fits and scored (>= 2).
    reference_vcpd_v : float, optional
        A published CPD [V] to compare with (reported only).
    profile_points : int
        Grid points of the ``V_cpd`` profile.
    window_variants_m : tuple of float
        Other ``exclude_closest_m`` values [m] whose refitted ``V_cpd`` give its systematic
        spread (the profile interval assumes independent residuals).
    jackknife_blocks : int
        Delete-a-block jackknife of ``V_cpd`` over this many contiguous blocks of fitted rows
        (0: none; else >= 3): a standard error that allows for residuals correlated in z.
    figures : callable, optional
        ``figures(report, spec, out_dir) -> paths`` (``afmlearn.plots.fm.fm_figures``).
    **calibration
        ``spring_constant_n_per_m``, ``amplitude_m``, ``resonance_frequency_hz`` (SI).

    Returns
    -------
    dict
        The report (as written).
    """
    if not (math.isfinite(exclude_closest_m) and exclude_closest_m >= 0.0):
        raise ValueError(f"exclude_closest_m must be >= 0 m, got {exclude_closest_m!r}")
    spec = data if isinstance(data, FMSpectroscopy) else read_fm_spectroscopy(data, **calibration)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    z = spec.z_piezo_m
    z_min = float(z.min())
    rows = np.flatnonzero(z >= z_min + exclude_closest_m)
    if rows.size < 5:
        raise ValueError(f"exclude_closest_m: leaves {rows.size} rows (< 5) to fit")
    win = spec.rows(rows)
    bounds = (z_min - 2e-9, z_min + 3e-9)
    fit_cols, test_cols = heldout_split(spec.shape[1], heldout_every)
    train, test = win.columns(fit_cols), win.columns(test_cols)

    kelvin = kelvin_parabolas(spec)
    models = {
        "baseline": FMFit(electrostatic=False, contact_bounds_m=bounds),
        "baseline_vcpd0": FMFit(vcpd_v=0.0, contact_bounds_m=bounds),
        "extended": FMFit(contact_bounds_m=bounds),
    }
    entries = {}
    for name, model in models.items():
        log.info("fitting %s on %d x %d", name, *train.shape)
        entries[name] = _entry(model.fit(train), test)
    base = entries["baseline"]["heldout_nrmse"]
    gain = 1.0 - entries["extended"]["heldout_nrmse"] / base if base > 0 else 0.0
    gain0 = (1.0 - entries["extended"]["heldout_nrmse"] / entries["baseline_vcpd0"]["heldout_nrmse"]
             if entries["baseline_vcpd0"]["heldout_nrmse"] > 0 else 0.0)

    final = FMFit(contact_bounds_m=bounds).fit(win, initial=models["extended"].law_)
    profile = final.profile_vcpd(win, n_points=profile_points)
    law = final.law_
    variants = {}
    for extra in window_variants_m:
        sub = np.flatnonzero(z >= z_min + extra)
        if sub.size >= 5 and extra != exclude_closest_m:
            variants[f"{extra:.3g}"] = FMFit(contact_bounds_m=bounds).fit(
                spec.rows(sub), initial=law).law_.vcpd_v
    jack = _jackknife_vcpd(win, law, bounds, jackknife_blocks)
    all_rows = FMFit(contact_bounds_m=bounds).fit(spec)
    near = np.flatnonzero(z < z_min + exclude_closest_m)
    # staged: the window's electrostatics held, one bias-independent short-range law (vdW +
    # DMT, own contact position and radius) fitted to what is left on all rows
    es_map = model_hz(spec, law)
    left = FMSpectroscopy(spec.frequency_shift_hz - es_map, z, spec.bias_v,
                          spec.spring_constant_n_per_m, spec.amplitude_m,
                          spec.resonance_frequency_hz)
    short = FMFit(electrostatic=False, contact_bounds_m=bounds).fit(left)
    staged_res = left.frequency_shift_hz - short.predict_hz(left)
    model_kelvin = kelvin_parabolas(FMSpectroscopy(
        model_hz(spec, law), z, spec.bias_v, spec.spring_constant_n_per_m, spec.amplitude_m,
        spec.resonance_frequency_hz))
    good = np.isfinite(kelvin["vcpd_v"][rows])
    report: dict[str, Any] = {
        "data": {"source": spec.source, "shape": list(spec.shape),
                 "z_piezo_range_m": [z_min, float(z.max())],
                 "bias_range_v": [float(spec.bias_v.min()), float(spec.bias_v.max())],
                 "spring_constant_n_per_m": spec.spring_constant_n_per_m,
                 "amplitude_m": spec.amplitude_m,
                 "resonance_frequency_hz": spec.resonance_frequency_hz},
        "window": {"exclude_closest_m": exclude_closest_m, "rows_fitted": int(rows.size),
                   "heldout_every": heldout_every, "columns_fitted": int(fit_cols.size),
                   "columns_heldout": int(test_cols.size)},
        "cause": "electrostatic" if gain > 0.1 else "none",
        "baseline": entries["baseline"], "baseline_vcpd0": entries["baseline_vcpd0"],
        "extended": entries["extended"], "gain": gain, "gain_over_vcpd0": gain0,
        "final": {"equation": equation(law), "law": law.to_dict(), "fit_rms_hz": final.rms_hz_},
        "vcpd": {"value_v": law.vcpd_v, "interval_95_v": [profile["low_v"], profile["high_v"]],
                 "profile": profile, "far_v": law.far_v,
                 "kelvin_fitted_rows_median_v": float(np.median(kelvin["vcpd_v"][rows][good])),
                 "kelvin_fitted_rows_range_v": [float(np.min(kelvin["vcpd_v"][rows][good])),
                                                float(np.max(kelvin["vcpd_v"][rows][good]))],
                 "reference_v": reference_vcpd_v,
                 "by_window_v": variants, "jackknife": jack,
                 "by_window_range_v": ([min([law.vcpd_v, *variants.values()]),
                                        max([law.vcpd_v, *variants.values()])])},
        "kelvin": {"z_piezo_m": z.tolist(), **{k: v.tolist() for k, v in kelvin.items()},
                   "model_vcpd_v": model_kelvin["vcpd_v"].tolist()},
        "residual": _residual_structure(win, law),
        "all_rows": {"equation": equation(all_rows.law_), "fit_rms_hz": all_rows.rms_hz_,
                     "law": all_rows.law_.to_dict(),
                     "row_rms_hz": _residual_structure(spec, all_rows.law_)["row_rms_hz"],
                     "window_law_rms_on_all_rows_hz": _residual_structure(spec, law)["rms_hz"],
                     "excluded_rows": (_residual_structure(spec.rows(near), all_rows.law_)
                                       if near.size else None)},
    }
    report["staged"] = {
        "equation": equation(short.law_), "law": short.law_.to_dict(),
        "rms_hz": float(np.sqrt(np.mean(staged_res**2))),
        "row_rms_hz": np.sqrt(np.mean(staged_res**2, axis=1)).tolist(),
        "excluded_rows": (_residual_parts(staged_res[near], spec.bias_v, law.vcpd_v)
                          if near.size else None)}
    report["figures"] = ([str(p.relative_to(out)) for p in figures(report, spec, out)]
                         if figures is not None else [])
    write_json(out / "report.json", jsonable(report))
    return report
