"""The law to quote when the data do not bound the contact exponent.

On one orbit (or a few short set-points of one free amplitude) the exponent of ``delta^p``
trades with ``a0`` and the contact stiffness along a flat valley: its 95 % profile interval
reaches the end of the profiled range and the fitted value (e.g. ``delta^3.49996``) is a point
on that valley, not a measurement. A user quotes the equation, so the identifier's outputs then
state the law at the sphere's Hertz/DMT exponent ``1.5`` (physics.md's baseline), with ``a0``
and every coefficient re-fitted there, and say that the exponent is fixed because it is not
identifiable; the unbounded interval stays in the text. The fit itself is not changed (model.json
and force.h5 keep the fitted law, which describes the orbit as well).

When the unbounded interval excludes ``1.5`` the data reject the sphere; then no exponent is
fixed and the text says which end of the interval is bounded and that the equation's exponent
is the profile's edge value.

:func:`fixed_exponent_law` needs only what the fit already holds (no new nonlinear fit):

- one orbit: ``a0`` profiled on the exponent profile's grid and every coefficient refitted by
  the same constrained least squares (a few linear solves);
- a joint output-error fit: the output-error profile's own fit at that exponent (kept by
  :class:`~afmlearn.identify.output_error.ExponentProfile` under ``fits``); absent: no refit,
  the text says the equation's exponent is unidentified;
- a joint equation-error fit: :func:`~afmlearn.identify.joint.support_fit` with ``a0``
  profiled, as :class:`~afmlearn.identify.joint.ExponentProfile` does at every point.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, final

import numpy as np
from numpy.typing import NDArray

from .joint_outputs import finite_number
from .library import AFMLibrary, Indentation
from .line_search import grid_then_bounded
from .model import IdentifiedModel

if TYPE_CHECKING:
    from .identifier import ForceIdentifier

__all__ = ["SPHERE_EXPONENT", "FixedExponentLaw", "fixed_exponent_law"]

FloatArray = NDArray[np.float64]

#: the sphere's Hertz/DMT exponent: the baseline law's (physics.md section 2)
SPHERE_EXPONENT = 1.5


@final
@dataclass(frozen=True)
class FixedExponentLaw:
    """What the outputs state about an exponent the data do not bound.

    Attributes
    ----------
    exponent : float or None
        The fixed exponent (None: not fixed, the data exclude it).
    model : IdentifiedModel or None
        The law re-fitted at ``exponent`` (None: no cheap refit, or not fixed).
    rise : float
        Profile statistic at ``exponent`` above the profile's minimum (the 95 % level is
        3.84), NaN when unknown.
    method : str
        How ``model`` was obtained (empty without one).
    text : str
        One clause for the terminal and the report.
    force : dict or None
        ``model``'s force on the identifier's samples with its 95 % band, conditional on the
        fixed exponent: ``force``, ``lo``, ``hi`` [k L_ref], each the shape of the
        identifier's ``force_`` (NaN band where none); None without ``model``.
    band : str
        What the band is (the files' description).
    """

    exponent: float | None
    model: IdentifiedModel | None
    rise: float
    method: str
    text: str
    force: dict[str, FloatArray] | None = None
    band: str = ""

    def record(self) -> dict[str, Any]:
        """JSON-able content for result.json's ``exponent_fixed``."""
        out: dict[str, Any] = {"exponent": self.exponent, "profile_rise": self.rise,
                               "method": self.method, "text": self.text}
        if self.model is not None:
            out["equation"] = self.model.equation()
            out["equation_si"] = self.model.equation_si()
            out["a0"] = self.model.a0
            out["si_terms"] = self.model.si_terms()
        return out


def fixed_exponent_law(ide: ForceIdentifier, *, exponent: float = SPHERE_EXPONENT
                       ) -> FixedExponentLaw | None:
    """The law at ``exponent`` when the fitted identifier's profile does not bound its exponent.

    Parameters
    ----------
    ide : ForceIdentifier
        Fitted (single orbit or joint).
    exponent : float
        The exponent to fix, default the sphere's 1.5.

    Returns
    -------
    FixedExponentLaw or None
        None when the exponent is bounded, or there is no contact term or no profile.
    """
    s = ide.summary_
    p = s.get("interaction_exponent")
    iv = s.get("interaction_exponent_interval")
    if p is None or iv is None or not all(finite_number(v) for v in iv) \
            or s.get("interaction_exponent_bounded") is not False:
        return None
    lo, hi = float(iv[0]), float(iv[1])
    where = f"95 % profile interval {lo:.2f}-{hi:.2f} reaches the end of the profiled range"
    if not lo - 1e-9 <= exponent <= hi + 1e-9:
        side = "below" if exponent < lo else "above"
        bound = (f"at least {lo:.2f}" if exponent < lo else f"at most {hi:.2f}")
        return FixedExponentLaw(
            exponent=None, model=None, rise=math.nan, method="",
            text=(f"interaction exponent {bound}, not bounded on the other side ({where}); "
                  f"the sphere's {exponent:g} lies {side} it, so the equation keeps the fitted "
                  f"delta^{p:.6g}, a value at the profile's edge, not an identified exponent"))
    if ide.orbit_ is not None:
        model, rise, method, force, band = _orbit_law(ide, float(p), exponent)
    else:
        model, rise, method, force, band = _joint_law(ide, float(p), exponent)
    own = ("the free fit also gave it" if abs(p - exponent) < 5e-3 else
           f"the free fit's {p:.2f} is one point of a flat valley")
    head = (f"interaction exponent {exponent:g} FIXED (sphere, Hertz/DMT): not identifiable "
            f"from these data ({where}; {own})")
    if model is None:
        text = (head + "; no refit at it is available, so the equation keeps "
                f"delta^{p:.6g}, NOT an identified exponent: do not quote it")
    else:
        text = (head + f"; equation re-fitted at {exponent:g} ({method}"
                + (f"; profile rise {rise:.2f}, 3.84 at 95 %" if finite_number(rise) else "")
                + ")")
    return FixedExponentLaw(exponent=exponent, model=model, rise=rise, method=method, text=text,
                            force=force if model is not None else None, band=band)


# ---------------------------------------------------------------------------- refits
def _contact_index(lib: AFMLibrary, p: float) -> int | None:
    js = [j for j, t in enumerate(lib.terms) if isinstance(t, Indentation) and t.p == p]
    return js[0] if js else None


def _with_exponent(lib: AFMLibrary, j: int, exponent: float) -> AFMLibrary:
    """``lib`` with term ``j`` at ``exponent`` (dropped when another term already has it)."""
    if any(isinstance(t, Indentation) and t.p == exponent and k != j
           for k, t in enumerate(lib.terms)):
        return lib.subset(np.arange(lib.n_terms) != j)
    return lib.replace(j, Indentation(float(exponent)))


def _best_a0(cost: Any, lo: float, hi: float, hint: float, n: int = 10) -> float:
    """``a0`` minimising ``cost`` over a geometric grid plus ``hint``, then refined between
    the best point's neighbours (the exponent profiles' own search)."""
    grid = np.unique(np.concatenate([np.geomspace(lo, hi, n), [hint]]))
    return grid_then_bounded(cost, grid, maxiter=8)[0]


_Refit = tuple[IdentifiedModel | None, float, str, "dict[str, FloatArray] | None", str]
_NONE: _Refit = (None, math.nan, "", None, "")


def _orbit_law(ide: ForceIdentifier, p: float, exponent: float) -> _Refit:
    """One orbit: ``a0`` profiled and every coefficient re-fitted at ``exponent``; its force
    with the bagging band of that refit (the fitted law's kind of band)."""
    from .joint import Bagging
    from .single import orbit_model
    from .single_outputs import orbit_force

    res = ide.orbit_
    assert res is not None
    pb = res.problem
    j = _contact_index(res.library, p)
    if j is None:
        return _NONE
    lib = _with_exponent(res.library, j, exponent)
    lo, hi = pb.a0_range
    a0 = _best_a0(lambda a: pb.support_rss(lib, a), lo, hi, res.a0)
    des = pb.design(lib, a0)
    try:
        coef = pb.refit(des, np.ones(des.theta.shape[1], bool))
    except (ValueError, np.linalg.LinAlgError):
        return _NONE
    r = des.y - des.theta @ coef
    rss = float(r @ r)
    rise = math.nan
    prof = ide.exponent_profile_
    if prof is not None and np.isfinite(prof[:, 1]).any() and rss > 0:
        rise = float(des.y.size * math.log(rss / float(np.nanmin(prof[:, 1]))))
    model = orbit_model(pb, lib, a0, coef, info={"exponent_fixed": exponent})
    samples = None
    if ide.n_bootstrap:
        samples = Bagging(n_bootstrap=ide.n_bootstrap, seed=ide.seed).run(
            pb, des)  # type: ignore[arg-type]
    fo = orbit_force(pb, model, lib, samples)
    force = {k: fo[k] for k in ("force", "lo", "hi")}
    return (model, rise, "a0 and every coefficient, equation error", force,
            f"the bagged refits at the fixed exponent {exponent:g} (a0 held)")


def _joint_law(ide: ForceIdentifier, p: float, exponent: float) -> _Refit:
    """Joint fit: the output-error profile's fit at ``exponent`` with its Gauss--Newton band
    (``a0`` and the coefficients), or an equation-error refit with its bootstrap band."""
    from .force_band import conditional_band
    from .joint import Bagging, support_fit
    from .joint_outputs import joint_model, orbit_inputs

    res = ide.joint_
    assert res is not None
    ex = res.exponent or {}
    if res.output_error is not None:
        fit = (ex.get("fits") or {}).get(round(float(exponent), 6))
        if fit is None:
            return _NONE
        prof = np.asarray(ex["profile"], float)
        rise = math.nan
        i = np.flatnonzero(np.isclose(prof[:, 0], exponent))
        if i.size and ex.get("dispersion"):
            rise = float((prof[i[0], 1] - np.nanmin(prof[:, 1])) / ex["dispersion"])
        model = joint_model(res, fit.coef(res.problem), fit.library, fit.a0,
                            info={"exponent_fixed": exponent, "joint": True})
        band = conditional_band(fit, orbit_inputs(res))
        force = {k: np.stack(v) for k, v in band.items()}
        return (model, rise, "the output-error profile's fit at this exponent", force,
                f"simultaneous Gauss-Newton band of the fit at the fixed exponent {exponent:g} "
                "(a0 and the force coefficients, delta method)")
    j = _contact_index(res.library, p)
    if j is None:
        return _NONE
    lib = _with_exponent(res.library, j, exponent)
    pb = res.problem
    lo, hi = pb.a0_range
    a0 = _best_a0(lambda a: support_fit(pb, lib, a)[1], lo, hi, res.a0)
    coef, rss, des = support_fit(pb, lib, a0)
    if not math.isfinite(rss):
        return _NONE
    model = joint_model(res, coef, lib, a0, info={"exponent_fixed": exponent, "joint": True})
    samples = Bagging(n_bootstrap=ide.n_bootstrap, seed=ide.seed).run(pb, des)
    ins = orbit_inputs(res)
    th = [lib.evaluate(dataclasses.replace(t, a0=a0)) for t in ins]
    f = np.stack([t @ coef[pb.n_lin:] for t in th])
    if samples.shape[0] >= 5:
        q = [np.percentile(samples[:, pb.n_lin:] @ t.T, [2.5, 97.5], axis=0) for t in th]
        lo, hi = np.stack([a for a, _ in q]), np.stack([b for _, b in q])
    else:
        lo = hi = np.full_like(f, np.nan)
    return (model, math.nan, "a0 and every coefficient, equation error",
            {"force": f, "lo": lo, "hi": hi},
            f"the bootstrap refits at the fixed exponent {exponent:g} (a0 held)")
