"""`analyse_curve`: baseline DMT sphere on the approach, contact exponent, adhesion
hysteresis, and the gain of the free exponent measured on the retraction (not fitted).

Per curve:

1. baseline: `ContactFit(exponent=1.5)` (DMT sphere) on the approach;
2. extension: `ContactFit(exponent=None)` (contact exponent free) on the approach;
3. held-out check: both approach fits predict the retraction's repulsive part (force above
   the retraction's own adhesion level: the adhesion neck is the hysteresis, not the contact
   law); ``gain = 1 - NRMSE(extended) / NRMSE(baseline)`` (design.md section 4 NRMSE);
4. adhesion hysteresis: the most negative force on each branch (jump-in on approach, pull-off
   on retraction) and the work of the loop ``∮ F dd`` between approach and retraction
   (> 0: energy dissipated per cycle) [J].
"""

from __future__ import annotations

from typing import Any

import numpy as np

from afmlearn.forcecurve.contact import Branch, ContactFit, branch
from afmlearn.io.instruments import ForceCurve
from afmlearn.metrics import nrmse

__all__ = ["analyse_curve"]


def analyse_curve(curve: ForceCurve, *, baseline_fraction: float = 0.3) -> dict[str, Any]:
    """Fit and compare the contact laws of one static curve (see module docstring).

    Returns
    -------
    dict
        ``baseline`` / ``extended`` (contact point [m], prefactor, exponent, adhesion [N], RMS
        on the approach [N], held-out NRMSE on the retraction), ``gain``, ``pull_off_n``,
        ``jump_in_n``, ``adhesion_hysteresis_n`` (pull-off minus jump-in), ``loop_work_j``,
        ``n_heldout``.
    """
    if not (np.any(curve.segment == 0) and np.any(curve.segment == 1)):
        raise ValueError("the curve needs both an approach (segment 0) and a retraction (1)")
    app = branch(curve, 0, baseline_fraction=baseline_fraction)
    ret = branch(curve, 1, baseline_fraction=baseline_fraction)
    base = ContactFit(exponent=1.5).fit(app)
    ext = ContactFit(exponent=None).fit(app)
    floor = float(np.min(ret.force_n))
    held = ret.force_n > floor + 0.5 * (np.max(ret.force_n) - floor)  # repulsive upper half
    heldout = Branch(ret.separation_m[held], ret.force_n[held])
    scores = {}
    for name, fit in (("baseline", base), ("extended", ext)):
        scores[name] = {
            "contact_point_m": fit.contact_point_m_, "prefactor": fit.prefactor_,
            "exponent": fit.exponent_, "adhesion_n": fit.adhesion_n_,
            "rms_approach_n": fit.rms_n_,
            "heldout_nrmse": float(nrmse(fit.predict(heldout.separation_m), heldout.force_n))}
    jump_in = -float(np.min(app.force_n))
    pull_off = -floor
    return {
        "baseline": scores["baseline"], "extended": scores["extended"],
        "gain": 1.0 - scores["extended"]["heldout_nrmse"] / scores["baseline"]["heldout_nrmse"],
        "jump_in_n": jump_in, "pull_off_n": pull_off,
        "adhesion_hysteresis_n": pull_off - jump_in,
        "loop_work_j": _loop_work(app, ret), "n_heldout": int(held.sum()),
    }


def _loop_work(app: Branch, ret: Branch) -> float:
    """``∫ (F_approach - F_retract) dd`` over the common separation range [J] (> 0 when the
    retraction is below the approach: energy dissipated)."""
    lo = max(app.separation_m.min(), ret.separation_m.min())
    hi = min(app.separation_m.max(), ret.separation_m.max())
    if not hi > lo:
        return float("nan")
    grid = np.linspace(lo, hi, 512)
    fa = _on(grid, app)
    fr = _on(grid, ret)
    return float(np.trapezoid(fa - fr, grid))


def _on(grid: np.ndarray, b: Branch) -> np.ndarray:
    order = np.argsort(b.separation_m)
    return np.interp(grid, b.separation_m[order], b.force_n[order])
