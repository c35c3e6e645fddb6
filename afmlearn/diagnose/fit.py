"""Fit a model structure: grid over its nonlinear parameters, then joint refinement.

The nonlinear vector is ``(a0, phi, *extension parameters)``; every evaluation solves the
linear sub-problem (:meth:`HarmonicBalance.solve`, variable projection). Stage 1 evaluates the
extension's grid at the baseline's ``a0`` and ``phi``; stage 2 refines the best grid points
jointly with ``a0`` and ``phi`` by bounded trust-region least squares on the whitened
residual.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import least_squares

from .balance import HarmonicBalance, Solution
from .hypotheses.base import AbstractHypothesis, Context, Parameter
from .output_error import OutputError
from .spec import ModelSpec

__all__ = ["fit_baseline", "fit_extension", "structure", "refine_output_error"]


def _to_u(p: Parameter, v: float) -> float:
    return math.log(v) if p.log else v


def _from_u(p: Parameter, u: float) -> float:
    return math.exp(u) if p.log else u


def _refine(hb: HarmonicBalance, build, params: Sequence[Parameter], start: Sequence[float],
            max_nfev: int) -> Solution:
    """Bounded least squares over ``params`` (values) from ``start``; ``build(values) -> spec``."""
    lo = np.array([_to_u(p, p.low) for p in params])
    hi = np.array([_to_u(p, p.high) for p in params])
    u0 = np.clip([_to_u(p, v) for p, v in zip(params, start, strict=True)], lo, hi)
    u0 = np.minimum(np.maximum(u0, lo + 1e-9 * (hi - lo)), hi - 1e-9 * (hi - lo))
    best: dict[str, Solution] = {}

    def fun(u: np.ndarray) -> np.ndarray:
        vals = tuple(_from_u(p, float(x)) for p, x in zip(params, u, strict=True))
        sol = hb.solve(build(vals), vals)
        if "s" not in best or sol.chi2 < best["s"].chi2:
            best["s"] = sol
        return sol.residual

    try:
        least_squares(fun, u0, bounds=(lo, hi), method="trf", x_scale="jac",
                      diff_step=1e-3, max_nfev=max_nfev)
    except (ValueError, np.linalg.LinAlgError):  # a degenerate start: keep what was seen
        if "s" not in best:
            fun(u0)
    return best["s"]


def fit_baseline(hb: HarmonicBalance, ctx: Context, *, n_a0: int = 10, n_phase: int = 16,
                 max_nfev: int = 200) -> Solution:
    """The baseline (1 mode, VdW--DMT sphere): grid over ``a0`` x drive phase, then refine.

    ``a0`` is an intermolecular distance: searched from 0.1 to 3 nm (and above the orbit's
    lowest gap, so the orbit can stay out of contact).
    """
    lo_a = max(0.1e-9 / ctx.length_m, 1e-4)
    hi_a = max(3e-9 / ctx.length_m, 2 * lo_a)
    a0_grid = np.geomspace(lo_a, hi_a, n_a0)
    phases = np.linspace(-math.pi, math.pi, n_phase, endpoint=False)
    scored = []
    for a0 in a0_grid:
        for ph in phases:
            s = hb.solve(ModelSpec(a0=float(a0), drive_phase=float(ph)), (float(a0), float(ph)))
            scored.append((s.chi2, float(a0), float(ph)))
    scored.sort()
    params = [Parameter("a0", lo_a, hi_a, (), log=True),
              Parameter("drive_phase", -4 * math.pi, 4 * math.pi, ())]
    best = None
    for _, a0, ph in scored[:3]:
        sol = _refine(hb, lambda v: ModelSpec(a0=v[0], drive_phase=v[1]), params, (a0, ph),
                      max_nfev)
        if best is None or sol.chi2 < best.chi2:
            best = sol
    assert best is not None
    return best


def fit_extension(hb: HarmonicBalance, base: Solution, hyp: AbstractHypothesis, ctx: Context,
                  *, max_nfev: int = 200) -> list[Solution]:
    """Fit ``hyp``'s extension of the baseline ``base`` on the harmonic balance.

    Returns up to ``hyp.n_starts`` solutions, best first: the best grid points, each refined
    jointly with ``a0`` and the drive phase (distinct starts for the output-error stage, which
    the equation error cannot rank reliably for forces that jump), and, if the search ended
    above the baseline, the nested point (the extension switched off) as well.
    """
    params = hyp.parameters(ctx)
    spec0 = base.spec
    grid = list(itertools.product(*[p.grid for p in params]))
    scored = []
    for vals in grid:
        s = hb.solve(hyp.extend(spec0, vals), (spec0.a0, spec0.drive_phase, *vals))
        scored.append((s.chi2, vals, s))
    scored.sort(key=lambda t: t[0])
    build, allp = structure(hyp, spec0, ctx)
    out = []
    for _, vals, _ in scored[:hyp.n_starts]:
        out.append(_refine(hb, build, allp, (spec0.a0, spec0.drive_phase, *vals), max_nfev))
    out.sort(key=lambda s: s.chi2)
    # every extension nests the baseline; a search that ends above it has failed to find
    # that point, so the nested limit (the baseline with the extension switched off) joins
    if out[0].chi2 > base.chi2:
        nv = hyp.nested_values(params)
        out.append(hb.solve(hyp.extend(spec0, nv), (spec0.a0, spec0.drive_phase, *nv)))
    return out


def structure(hyp: AbstractHypothesis | None, spec0: ModelSpec, ctx: Context
              ) -> tuple[Callable[[Sequence[float]], ModelSpec], list[Parameter]]:
    """``build(values) -> spec`` and the parameters ``(a0, phi, *extension)`` around ``spec0``.

    ``a0`` may move by a factor 3 and the drive phase by 0.5 rad from the baseline's values.
    """
    params = [Parameter("a0", spec0.a0 / 3.0, spec0.a0 * 3.0, (), log=True),
              Parameter("drive_phase", spec0.drive_phase - 0.5, spec0.drive_phase + 0.5, ())]
    if hyp is not None:
        params += hyp.parameters(ctx)

    def build(v: Sequence[float]) -> ModelSpec:
        s = spec0.replace(a0=float(v[0]), drive_phase=float(v[1]))
        return s if hyp is None else hyp.extend(s, v[2:])

    return build, params


def refine_output_error(oe: OutputError, starts: Sequence[Solution],
                        hyp: AbstractHypothesis | None, base: Solution, ctx: Context, *,
                        max_nfev: int = 25) -> tuple[Solution, bool]:
    """Output-error refinement from each start; the best refined solution.

    ``hyp`` None refines the baseline. ``base`` is the frame of the bounds: the baseline's
    equation-error solution when refining it, the refined baseline for an extension; in that
    case a start at the nested point (the refined baseline with the extension switched off)
    is added, so the extension, which contains the baseline, cannot end worse than it.
    """
    build, params = structure(hyp, base.spec, ctx)
    starts = list(starts)
    if hyp is not None:
        nv = hyp.nested_values(params[2:])
        vals = (*base.values[:2], *nv)
        spec = build(vals)
        coef = np.concatenate([base.coef, np.zeros(spec.n_force - base.spec.n_force)])
        starts.append(Solution(spec=spec, coef=coef, residual=base.residual, chi2=base.chi2,
                               values=vals))
    best: tuple[Solution, bool] | None = None
    for start in starts:
        out, ok = oe.refine(start, build, params, max_nfev=max_nfev)
        if best is None or out.chi2 < best[0].chi2:
            best = (out, ok)
    assert best is not None
    return best
