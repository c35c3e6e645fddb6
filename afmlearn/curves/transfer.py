"""Gain on other curves of the same tip: a law fitted on one curve predicts a whole other curve
(recorded at another free amplitude), with only the surface position and the drive frequency
refitted there (issue 14, part 3: data not fitted)."""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy import optimize

from simulator.lockin import LockIn

from .curve import Curve
from .diagnose import heldout_nrmse
from .fit import OFFSET, OMEGA, wrap_phase
from .law import CurveLaw
from .model import SlowFlowModel

log = logging.getLogger(__name__)

__all__ = ["law_from_parameters", "rescale_law", "transfer_gains", "transfer_nrmse"]

#: law fields that are lengths (scale with 1 / length unit)
_LENGTHS = ("a0", "decay_length", "radius", "neck", "far_decay_length")


def law_from_parameters(values: dict[str, float], length_m: float, *, a0_m: float = 0.3e-9,
                        tip_radius_m: float = 10e-9) -> CurveLaw:
    """The :class:`CurveLaw` of a report's fitted ``parameters`` on a curve of free amplitude
    ``length_m`` [m] (its length unit; ``a0`` and the radius as the fitter holds them, SI)."""
    base = CurveLaw(a0=a0_m / length_m, radius=tip_radius_m / length_m)
    fields = set(base.parameters())
    return base.replace(**{k: float(v) for k, v in values.items() if k in fields})


def rescale_law(law: CurveLaw, ratio: float) -> CurveLaw:
    """The same SI force law in another length unit: ``ratio = L_from / L_to``.

    Forces are in units of ``k L``; a force ``F(z)`` in SI is unchanged when lengths become
    ``z / L_to``: lengths scale by ``ratio``, the ``1/z**2`` coefficients (VdW, electrostatic)
    by ``ratio**3``, the contact stiffness by ``ratio**(1 - p)``, the viscoelastic term by
    ``ratio**-0.5`` and the damping coefficient not at all (rates are per unit ``omega0 t``).
    """
    if not (math.isfinite(ratio) and ratio > 0):
        raise ValueError(f"ratio must be a finite number > 0, got {ratio!r}")
    r = float(ratio)
    ch: dict[str, float] = {k: getattr(law, k) * r for k in _LENGTHS}
    ch["vdw"] = law.vdw * r**3
    ch["electrostatic"] = law.electrostatic * r**3
    ch["stiffness"] = law.stiffness * r ** (1.0 - law.exponent)
    ch["visco"] = law.visco * r**-0.5
    return law.replace(**ch)


class _Fixed:
    """A fitted-law stand-in for :func:`heldout_nrmse`: ``predict(curve)`` of a fixed law with
    a surface position and a drive frequency."""

    def __init__(self, law: CurveLaw, model: SlowFlowModel, offset: float) -> None:
        self.law, self.model, self.offset = law, model, offset

    def predict(self, curve: Curve):
        return self.model.predict(self.law, curve.tau, curve.z_piezo - self.offset)


def _model(curve: Curve, omega: float, lockin: LockIn | None, step: float) -> SlowFlowModel:
    q = curve.quality_factor
    return SlowFlowModel(quality_factor=q, omega=omega, drive=math.hypot(1 - omega**2, omega / q),
                         lockin=lockin, step=step)


def transfer_nrmse(law: CurveLaw, source_length_m: float, curve: Curve, *,
                   lockin: LockIn | None = None, step: float = 4.0 * math.pi,
                   max_nfev: int = 15) -> dict[str, Any]:
    """Predict ``curve`` with a law fitted on another curve of the same tip.

    Parameters
    ----------
    law : CurveLaw
        Fitted on a curve whose free amplitude (length unit) is ``source_length_m`` [m].
    curve : Curve
        The other curve; only its surface position (piezo coordinate of zero gap) and the
        drive frequency / f0 are fitted, on its approach.
    lockin : LockIn or None
    step : float
        Slow-flow grid (dimensionless).
    max_nfev : int
        Least-squares evaluations of the two nuisances.

    Returns
    -------
    dict
        ``nrmse`` (whole curve), ``nrmse_retraction``, ``offset``, ``omega`` (the fitted
        nuisances, dimensionless).
    """
    tl = rescale_law(law, source_length_m / curve.length_m)
    app = curve.segment == 0
    w0 = SlowFlowModel.for_curve(curve).omega

    def resid(x):
        a, p = _model(curve, x[1], lockin, step).predict(tl, curve.tau, curve.z_piezo - x[0])
        r = np.concatenate([(a - curve.amplitude)[app],
                            wrap_phase(p - curve.phase)[app] / (np.pi / 2)])
        return np.where(np.isfinite(r), r, 1e3)

    sel = app & (curve.amplitude > 0.2) & (curve.amplitude < 0.9)
    guess = (float(np.median(curve.z_piezo[sel] - curve.amplitude[sel])) if sel.any()
             else float(np.min(curve.z_piezo[app])) - 1.0)
    scan = [guess + d for d in np.linspace(-0.5, 0.5, 11)]
    costs = [float(np.sum(resid(np.array([o, w0])) ** 2)) for o in scan]
    x0 = np.array([scan[int(np.argmin(costs))], w0])
    lo, hi = np.array([x0[0] - 1.0, w0 - 0.005]), np.array([x0[0] + 1.0, w0 + 0.005])
    res = optimize.least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", diff_step=1e-4,
                                 max_nfev=max_nfev)
    fixed = _Fixed(tl, _model(curve, float(res.x[1]), lockin, step), float(res.x[0]))
    every = np.ones(curve.n, dtype=bool)
    return {"nrmse": heldout_nrmse(fixed, curve, every),
            "nrmse_retraction": heldout_nrmse(fixed, curve, curve.segment == 1),
            OFFSET: float(res.x[0]), OMEGA: float(res.x[1])}


def transfer_gains(summary: dict[str, Any], folder: str | os.PathLike[str], *,
                   n_sources: int = 4, n_targets: int = 4, group: str | None = None,
                   step: float = 4.0 * math.pi,
                   load: Callable[[Path], tuple[Curve, LockIn | None]] | None = None
                   ) -> dict[str, Any]:
    """Gain on other curves: each source curve's baseline and extended laws predict whole
    curves of the same tip at other free amplitudes.

    Parameters
    ----------
    summary : dict
        ``analyze_folder``'s summary (rows with ``file``, ``group``, ``cause``,
        ``free_amplitude_m``, ``parameters`` and ``baseline_parameters``).
    folder : path
        The folder the rows' ``file`` are relative to.
    n_sources, n_targets : int
        Sources: curves with a named cause, spread over the free amplitudes; targets: the
        other curves of the same group spread over the free amplitudes.
    group : str or None
        Only this group (default: every group).
    load : callable
        ``load(path) -> (curve, lockin)`` (default :func:`afmlearn.curves.analyze.load_curve`).

    Returns
    -------
    dict
        ``pairs`` (source, target, free amplitudes, cause, NRMSE of both laws on the whole
        target curve, ``gain = 1 - nrmse_ext / nrmse_base``), ``median_gain``,
        ``gain_positive`` (fraction of pairs).
    """
    if load is None:
        from .analyze import load_curve as load
    rows = [r for r in summary["curves"] if "cause" in r
            and (group is None or r["group"] == group)]
    named = sorted((r for r in rows if r["cause"] != "none"),
                   key=lambda r: r["free_amplitude_m"])
    pick = _spread(named, n_sources)
    pairs = []
    cache: dict[str, tuple[Curve, LockIn | None]] = {}
    for src in pick:
        others = sorted((r for r in rows if r["group"] == src["group"]
                         and r["file"] != src["file"]), key=lambda r: r["free_amplitude_m"])
        ls = src["free_amplitude_m"]
        base = law_from_parameters(src["baseline_parameters"], ls)
        ext = law_from_parameters(src["parameters"], ls)
        for tgt in _spread(others, n_targets):
            if tgt["file"] not in cache:
                cache[tgt["file"]] = load(Path(folder) / tgt["file"])
            curve, lockin = cache[tgt["file"]]
            b = transfer_nrmse(base, ls, curve, lockin=lockin, step=step)
            e = transfer_nrmse(ext, ls, curve, lockin=lockin, step=step)
            pairs.append({"source": src["file"], "target": tgt["file"], "cause": src["cause"],
                          "source_free_amplitude_m": ls,
                          "target_free_amplitude_m": curve.length_m,
                          "nrmse_baseline": b["nrmse"], "nrmse_extended": e["nrmse"],
                          "gain": 1.0 - e["nrmse"] / b["nrmse"] if b["nrmse"] > 0
                          else float("nan")})
            log.info("transfer %s -> %s: gain %.3f", src["file"], tgt["file"],
                     pairs[-1]["gain"])
    g = np.array([p["gain"] for p in pairs], dtype=float)
    return {"pairs": pairs, "median_gain": float(np.median(g)) if g.size else float("nan"),
            "gain_positive": float(np.mean(g > 0)) if g.size else float("nan")}


def _spread(rows: list[dict], n: int) -> list[dict]:
    """``n`` rows evenly spread over a sorted list (all when there are fewer)."""
    if len(rows) <= n:
        return list(rows)
    idx = np.unique(np.round(np.linspace(0, len(rows) - 1, n)).astype(int))
    return [rows[i] for i in idx]
