"""Fit a model structure jointly over the observations: grid, then joint refinement.

The nonlinear vector is ``(a0, *extension parameters)`` shared by every observation plus one
drive phase per observation; every evaluation solves the linear sub-problem
(:meth:`JointBalance.solve`, variable projection). Stage 1 evaluates the extension's grid at
the base model's ``a0`` and phases; stage 2 refines the best grid points jointly with ``a0``
and the phases by bounded trust-region least squares on the whitened residual. The
output-error stage (:func:`refine_output_error`) then fits each candidate's own periodic
orbits, with the phases projected out in closed form.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from .balance import Solution
from .hypotheses.base import AbstractHypothesis, Context, Parameter
from .joint import JointBalance
from .output_error import OutputError
from .spec import ModelSpec

__all__ = ["A0_MIN_M", "A0_MAX_M", "fit_baseline", "fit_extension", "structure",
           "refine_balance", "refine_output_error", "scan_starts", "energy_starts", "phase_starts",
           "baseline_grid_starts", "E_STAR_GRID_PA", "HAMAKER_GRID_J", "Build"]

#: ``build(values) -> spec`` for the nonlinear values ``(a0, *extension)``
Build = Callable[[Sequence[float]], ModelSpec]

#: range of the contact onset ``a0`` [m] searched by the baseline (an intermolecular distance)
A0_MIN_M = 0.1e-9
A0_MAX_M = 3e-9


def _to_u(p: Parameter, v: float) -> float:
    return math.log(v) if p.log else v


def _from_u(p: Parameter, u: float) -> float:
    return math.exp(u) if p.log else u


def refine_balance(jb: JointBalance, build: Build, params: Sequence[Parameter],
                   start: Sequence[float], phases: Sequence[float], phase_width: float | None,
                   max_nfev: int, *, project: int = 2) -> Solution:
    """Bounded least squares over ``params`` from ``start``; the phases are free within
    ``phase_width`` of ``phases``, or (``phase_width`` None) projected out
    (:meth:`JointBalance.solve` with ``project``) starting from ``phases``."""
    free = phase_width is not None
    ph0 = list(phases)
    n_ph = len(ph0) if free else 0
    w = float(phase_width) if free else 0.0
    lo = np.array([_to_u(p, p.low) for p in params] + [ph - w for ph in ph0[:n_ph]])
    hi = np.array([_to_u(p, p.high) for p in params] + [ph + w for ph in ph0[:n_ph]])
    u0 = np.array([_to_u(p, v) for p, v in zip(params, start, strict=True)] + ph0[:n_ph])
    u0 = np.minimum(np.maximum(u0, lo + 1e-9 * (hi - lo)), hi - 1e-9 * (hi - lo))
    k = len(params)
    best: dict[str, Solution] = {}

    def fun(u: np.ndarray) -> np.ndarray:
        vals = tuple(_from_u(p, float(x)) for p, x in zip(params, u[:k], strict=True))
        sol = (jb.solve(build(vals), u[k:], vals) if free else
               jb.solve(build(vals), ph0, vals, project=project))
        if "s" not in best or sol.chi2 < best["s"].chi2:
            best["s"] = sol
        if not math.isfinite(sol.chi2):
            # no finite columns here (bounded_lstsq): a large finite residual, so that the
            # trust region steps back instead of the optimiser failing on inf / NaN
            return np.full(sol.residual.size, 1e6)
        return sol.residual

    fun(u0)
    if u0.size and math.isfinite(best["s"].chi2):
        try:
            least_squares(fun, u0, bounds=(lo, hi), method="trf", x_scale="jac",
                          diff_step=1e-3, max_nfev=max_nfev)
        except np.linalg.LinAlgError:  # a degenerate start: keep the best point seen
            pass
    return best["s"]


def fit_baseline(jb: JointBalance, ctx: Context, *, n_a0: int = 10,
                 max_nfev: int = 200) -> Solution:
    """The baseline (1 mode, VdW--DMT sphere): grid over ``a0``, then refine with the phases.

    ``a0`` is an intermolecular distance: searched from 0.1 to 3 nm. At each grid point the
    phases come from the relaxed problem (:meth:`JointBalance.initial_phases`).
    """
    lo_a = max(A0_MIN_M / ctx.length_m, 1e-4)
    hi_a = max(A0_MAX_M / ctx.length_m, 2 * lo_a)
    scored = []
    for a0 in np.geomspace(lo_a, hi_a, n_a0):
        spec = ModelSpec(a0=float(a0))
        ph = jb.initial_phases(spec)
        s = jb.solve(spec, ph, (float(a0),))
        scored.append((s.chi2, float(a0), ph))
    scored.sort(key=lambda t: t[0])
    params = [Parameter("a0", lo_a, hi_a, (), log=True)]
    best = None
    for _, a0, ph in scored[:3]:
        sol = refine_balance(jb, lambda v: ModelSpec(a0=v[0]), params, (a0,), ph, None,
                             max_nfev, project=3)
        if best is None or sol.chi2 < best.chi2:
            best = sol
    assert best is not None
    return best


def fit_extension(jb: JointBalance, base: Solution, hyp: AbstractHypothesis, ctx: Context,
                  *, max_nfev: int = 200, n_starts: int | None = None) -> list[Solution]:
    """Fit ``hyp``'s extension of ``base`` (equation error, all observations at once).

    Returns up to ``n_starts`` (default ``hyp.n_starts``) solutions, best first: the best grid
    points, each refined jointly with ``a0`` (the phases projected out), and, if the search
    ended above the base model, the nested point (the extension switched off).

    The grid is evaluated from the base model's phases and, when every observation has a
    recorded drive phase, also from the recorded phases (:func:`phase_starts`); each start is
    refined from the phases it was scored at.
    """
    params = hyp.parameters(ctx)
    spec0 = base.spec
    grid = list(itertools.product(*[p.grid for p in params]))
    factors = tuple(float(f) for f in hyp.a0_grid)
    onsets = [spec0.a0 * f for f in factors]
    if ctx.a0_max is not None:
        # set-point series: also the baseline's whole onset range (a conservative base moves
        # a0 out to mimic a loss: measured 8.6x the drawn one on a seed-2026 damping series,
        # where the grid at the base's a0 put the damping term's contact off, chi2 601 against
        # the drawn law's 345)
        lo_a = max(A0_MIN_M / ctx.length_m, 1e-4)
        onsets += np.geomspace(lo_a, max(float(ctx.a0_max), 2 * lo_a), 6).tolist()
    scored = []
    for phases in phase_starts(jb, base):
        for a0 in onsets:
            spec_f = spec0.replace(a0=float(a0))
            for vals in grid:
                s = jb.solve(hyp.extend(spec_f, vals), phases, (spec_f.a0, *vals), project=1)
                scored.append((s.chi2, spec_f.a0, vals, phases))
    scored.sort(key=lambda t: t[0])
    build, allp = structure(hyp, spec0, ctx)
    out = [refine_balance(jb, build, allp, (a0, *vals), phases, None, max_nfev)
           for _, a0, vals, phases in scored[:n_starts or hyp.n_starts]]
    if len(factors) > 1:
        # one start per factor with a0 held there (a free a0 walks back to the base's basin);
        # the caller ranks them by output error (the equation error misranks the onsets:
        # measured 2346 vs 1012 by equation error, 461 vs 884 by output error)
        for f in factors:
            a0 = spec0.a0 * f
            _, _, vals, phases = min((t for t in scored if t[1] == a0), key=lambda t: t[0])
            held = [Parameter("a0", a0 * (1 - 1e-9), a0 * (1 + 1e-9), (), log=True), *allp[1:]]
            out.append(refine_balance(jb, build, held, (a0, *vals), phases, None, max_nfev))
    out.sort(key=lambda s: s.chi2)
    if out[0].chi2 > base.chi2:
        nv = hyp.nested_values(params)
        out.append(jb.solve(hyp.extend(spec0, nv), base.phases, (spec0.a0, *nv)))
    return out


def phase_starts(jb: JointBalance, base: Solution, *, tol: float = 0.1
                 ) -> list[tuple[float, ...]]:
    """The drive phases an extension's equation-error grid starts from: ``base``'s, and the
    recorded ones (the phase priors' means) when every observation has one and some
    observation's phase differs from ``base``'s by more than ``tol`` rad (modulo 2 pi).

    Why: a model without the loss the data hold can balance the drive's energy only by
    shifting the drive phase, so a conservative baseline's phases sit far from the recorded
    ones (measured on a seed-2026 long-range-damping series, 8 set-points: up to 0.85 rad off
    recorded phases of prior SD 0.02 rad), and the linear solve's few phase iterations do not
    bring them back. Grid points evaluated from there put the damping term at ``a0`` 2.5x the
    drawn one with the contact term off (equation error 24,451; output-error fit 11,364, the
    visco-elastic term named); from the recorded phases the equation error at the drawn law is
    387 and the damping fit reaches 310 (the drawn law: 310.5 exact, 297 refitted).
    """
    out = [tuple(float(p) for p in base.phases)]
    priors = jb.phase_priors
    if priors and all(p is not None for p in priors):
        rec = tuple(float(p[0]) for p in priors)
        gap = np.angle(np.exp(1j * (np.asarray(rec) - np.asarray(out[0]))))
        if rec and float(np.max(np.abs(gap))) > tol:
            out.append(rec)
    return out


def scan_starts(oe: OutputError, jb: JointBalance, base_hb: Solution, current: Solution,
                hyp: AbstractHypothesis, ctx: Context, n: int) -> list[Solution]:
    """Output-error starts from the extension's grid: the ``n`` best grid points by equation
    error (one per value of the first parameter), each placed on ``current``'s point (its
    ``a0`` and coefficients; the new force columns at the grid point's equation-error values,
    a contact term switched off moved off its bound, :func:`_off_bound`) and scored by
    output error (``chi2`` of the returned solutions; best first).

    For a second mode the equation error ranks the frequency ratio wrongly: it runs the force
    through the measured orbit, in which a weakly damped mode near a harmonic of the drive
    responds resonantly. Measured on a hidden-mode series (ratio 6.29, Q2 714): its best start
    (ratio 5.89) gave output-error chi2 2,357 against the baseline's 633, and the refinement
    switched the mode off (drop 0, equation-error drop 423); started at the true ratio, 293.
    """
    if hyp.energy_balance_start:
        starts = energy_starts(oe, current, hyp, ctx)
        if starts:          # none without a calibrated drive and recorded phases: the grid scan
            return starts
    params = hyp.parameters(ctx)
    scored = []
    for vals in itertools.product(*[p.grid for p in params]):
        s = jb.solve(hyp.extend(base_hb.spec, vals), base_hb.phases, (base_hb.spec.a0, *vals),
                     project=1)
        scored.append((s.chi2, vals, s))
    scored.sort(key=lambda t: t[0])
    build, _ = structure(hyp, current.spec, ctx)
    seen: set[float | None] = set()
    out = []
    for _, vals, ee in scored:
        if len(out) >= n:
            break
        first = vals[0] if vals else None
        if first in seen:
            continue
        seen.add(first)
        v = (current.values[0], *vals)
        spec = build(v)
        coef = _off_bound(spec, spec.embed(current.spec, current.coef))
        new_keys = set(spec.term_keys()) - set(current.spec.term_keys())
        theirs = ee.spec.term_keys()
        for j, key in enumerate(spec.term_keys()):
            if key in new_keys and key in theirs:
                coef[3 + j] = ee.coef[3 + theirs.index(key)]
        r, ok, phases = oe.residual(spec, coef)
        if not ok:
            continue
        out.append(Solution(spec=spec, coef=coef, residual=r, chi2=float(r @ r), values=v,
                            phases=tuple(phases)))
    out.sort(key=lambda s: s.chi2)
    return out


def energy_starts(oe: OutputError, current: Solution, hyp: AbstractHypothesis,
                  ctx: Context, *, max_nfev: int = 20) -> list[Solution]:
    """Output-error starts of a dissipative extension from the energy balance per set-point.

    On each measured orbit the drive puts in ``E_in = T <(B cos(theta - phi) - D x') x'>`` per
    period (calibrated lever: ``D = 1/Q``, ``B`` the calibrated drive amplitude, ``phi`` the
    recorded phase) minus the work of the conservative model's force terms; the new column's
    coefficient is the least-squares ratio of that to the column's work on the orbits (one
    coefficient for all set-points, of the column's allowed sign). Starts are made at
    ``current``'s point (its ``a0`` and conservative coefficients, the lever's set to the
    calibrated ones) for the ``hyp.energy_scan`` points of the extension's grid whose one
    coefficient carries the set-points' energies best. Each is shot from the orbits the output
    error held on entry (continuation in the new coefficient), so that no start depends on
    another or on the order of the grid, and refined by output error (``max_nfev``
    evaluations); the output error holds the entry orbits again on return. Returns the starts
    best first (``chi2``: output error); empty without a calibrated drive and phase on every
    orbit.

    Why: a conservative baseline moves the contact onset out (2.8-7x) and the equation error
    then gives a visco-elastic coefficient ~12x too small; measured (helper D, session 6) on a
    visco series: refined output error 9,976 from the equation-error start, 844 from this one
    (the generating law refitted: 309).
    """
    orbits = [hb.orbit for hb in oe.jb.balances]
    priors = oe.jb.phase_priors
    if any(o.drive_amplitude is None for o in orbits) or any(p is None for p in priors):
        return []
    warm = oe.snapshot()
    d = 1.0 / orbits[0].quality_factor
    spec0 = current.spec
    coef0 = np.array(current.coef, float)
    coef0[1], coef0[2] = d, float(orbits[0].drive_amplitude)
    T = [2.0 * np.pi / o.omega for o in orbits]
    e_in = []
    for o, pr, t in zip(orbits, priors, T, strict=True):
        x, v, _ = o.true_orbit(spec0)
        z = o.gap - x
        work = spec0.columns(z, -v, spec0.state(z)) @ coef0[3:3 + spec0.n_force]
        drive = float(o.drive_amplitude) * np.cos(o.theta - pr[0])
        e_in.append(np.mean((drive - d * v - work) * v) * t)
    e_in = np.asarray(e_in)
    scored = []
    for vals in itertools.product(*[p.grid for p in hyp.parameters(ctx)]):
        spec = hyp.extend(spec0, vals)
        new = [j for j, k in enumerate(spec.term_keys()) if k not in spec0.term_keys()]
        if len(new) != 1:
            continue
        j = new[0]
        e = []
        for o, t in zip(orbits, T, strict=True):
            x, v, _ = o.true_orbit(spec)
            z = o.gap - x
            e.append(np.mean(spec.columns(z, -v, spec.state(z))[:, j] * v) * t)
        e = np.asarray(e)
        ee = float(e @ e)
        c = float(e @ e_in) / ee if ee > 0 else 0.0
        if c == 0.0 or spec.signs()[j] * c < 0:
            continue
        # how well one coefficient carries the loss of every set-point: ranks the grid
        scored.append((float(np.sum((e_in - c * e) ** 2)), (spec0.a0, *vals), spec, j, c))
    scored.sort(key=lambda t: t[0])
    build, params = structure(hyp, spec0, ctx)
    out = []
    for _, v0, spec, j, c in scored[:hyp.energy_scan]:
        oe.restore(warm)        # every start from the orbits held on entry
        coef = spec.embed(spec0, coef0)
        start = None
        for frac in (0.125, 0.25, 0.5, 1.0):
            # continuation in the coefficient: the orbits are shot warm from the previous
            # fraction's (shot at once from the conservative model's, they do not converge)
            coef = coef.copy()
            coef[3 + j] = frac * c
            r, ok, phases = oe.residual(spec, coef)
            if not ok:
                break
            start = Solution(spec=spec, coef=coef, residual=r, chi2=float(r @ r), values=v0,
                             phases=tuple(phases))
        if start is None:
            continue
        if max_nfev > 0:
            # the start sits far from the output-error optimum (measured on a constructed
            # visco series: 5.2e6 at the start; 188 after the diagnosis' 10 joint
            # iterations, with a held-out error above the damping term's, 165 after 30, the
            # truth refitted 162; 12 evaluations here instead of 20: 1,074 instead of 238)
            ref, ok = oe.refine(start, build, params, max_nfev=max_nfev)
            if ok and ref.chi2 < start.chi2:
                start = ref
        out.append(start)
    oe.restore(warm)
    out.sort(key=lambda s: s.chi2)
    return out


#: physical ranges of the baseline's output-error start grid (:func:`baseline_grid_starts`):
#: reduced modulus E* [Pa] (soft polymer to oxide) and Hamaker constant [J]
E_STAR_GRID_PA = (0.3e9, 1e9, 3e9, 10e9, 30e9)
HAMAKER_GRID_J = (0.3e-19, 1e-19, 3e-19, 10e-19)


def baseline_grid_starts(oe: OutputError, base: Solution, ctx: Context, *, n: int = 3,
                         n_a0: int = 7) -> list[Solution]:
    """The baseline's ``n`` best output-error starts on a grid of physical laws, best first.

    The VdW--DMT sphere on the recording's tip radius ``R`` (``ctx.tip_radius``) with ``a0``
    on ``n_a0`` points from 0.1 to 3 nm, E* in :data:`E_STAR_GRID_PA` and the Hamaker
    constant in :data:`HAMAKER_GRID_J` (``c_vdw = -H R / (6 k L^3)``, ``c_contact = (4/3) E*
    sqrt(R L) / k``), with the calibrated lever (``K = 1``, ``D = 1/Q``, ``B`` the
    calibrated drive; ``base``'s where there is none): each point is shot cold from the
    measured orbits at the recorded phases (``base``'s without) and scored by output error;
    the ``n`` best are returned (``chi2``: their output error; empty if none shoots). ``oe``
    holds the orbits of entry again on return.

    Why: the equation error can put the baseline far from any law that shoots. Measured on a
    seed-2026 neck series redrawn with new noise only (8 set-points, 200 samples/period, 1 %):
    every equation-error start had a contact stiffness ~25x below the fitted one (0.05-0.15
    against 4.5 k L_ref^-0.5), its orbits ended 8.4e6 above the data or did not converge, and
    the baseline stayed there (the original noise draw: 584). The grid's best start by output
    error need not refine best (there: 37,451 -> 27,793, the next three 80,726-114,909 ->
    541.3), so the caller refines ``n`` of them.
    """
    orbits = [hb.orbit for hb in oe.jb.balances]
    sc = oe.scales
    L, k = float(sc.length), float(sc.spring_constant)
    r_m = float(ctx.tip_radius) * L
    coef0 = np.array(base.coef, float)
    if all(o.drive_amplitude is not None for o in orbits):
        coef0[:3] = 1.0, 1.0 / float(orbits[0].quality_factor), float(orbits[0].drive_amplitude)
    priors = oe.jb.phase_priors
    phases = ([float(p[0]) for p in priors] if priors and all(p is not None for p in priors)
              else list(base.phases))
    keys = ModelSpec(a0=1.0).term_keys()
    iv, ic = 3 + keys.index("vdw"), 3 + keys.index("contact")
    lo_a = max(A0_MIN_M / L, 1e-4)
    hi_a = max(A0_MAX_M / L, 2 * lo_a)
    entry = oe.snapshot()
    out: list[Solution] = []
    for a0 in np.geomspace(lo_a, hi_a, n_a0):
        spec = ModelSpec(a0=float(a0))
        for e_star in E_STAR_GRID_PA:
            for hamaker in HAMAKER_GRID_J:
                coef = coef0.copy()
                coef[iv] = -hamaker * r_m / (6.0 * k * L**3)
                coef[ic] = 4.0 / 3.0 * e_star * math.sqrt(r_m * L) / k
                oe.restore(({}, {}, phases))
                r, ok, ph = oe.residual(spec, coef)
                c2 = float(r @ r)
                if ok and math.isfinite(c2):
                    out.append(Solution(spec=spec, coef=coef, residual=r, chi2=c2,
                                        values=(float(a0),), phases=tuple(ph)))
    oe.restore(entry)
    out.sort(key=lambda sol: sol.chi2)
    return out[:n]


def _branch(oe: OutputError, start: Solution, warm: Any) -> None:
    """Leave ``oe`` holding the orbits from which ``start``'s model fits best: shot from
    ``warm`` (an :meth:`OutputError.snapshot`; None: the orbits it holds) and shot cold, from
    the measured orbits at ``start``'s phases; the one with the lower output error is kept.

    Where two stable orbits coexist at a set-point (attractive and tapping branches) the
    shooting start decides the branch, and the orbits of another model need not lead to the
    one that fits: measured on a constructed visco series, the visco-elastic fit (chi2 248)
    re-shot from the orbits the diagnosis held last gave 6,617, shot cold 248 again.
    """
    if warm is None:
        return
    oe.restore(warm)
    held = oe.snapshot()
    r, ok, _ = oe.residual(start.spec, start.coef)
    first = float(r @ r) if ok else math.inf
    shot = oe.snapshot()
    oe.restore(({}, {}, list(start.phases) if start.phases else held[2]))
    r, ok, _ = oe.residual(start.spec, start.coef)
    if not (ok and float(r @ r) < first):
        oe.restore(shot)


def _grid_refined(oe: OutputError, start: Solution, base: Solution, ctx: Context,
                  max_nfev: int) -> tuple[Solution, bool, Any, Build, list[Parameter]] | None:
    """The baseline refined from :func:`baseline_grid_starts` (each shot cold, the best kept)
    when the grid's best start has a lower output error than ``start`` (shot from the orbits
    held): ``(solution, converged, its orbits, build, parameters)``, each refined in the
    structure around its own start (``a0`` within a factor 3 of the grid point's), else None.
    ``oe`` holds the orbits of entry again on return, so that the refinement of ``start`` that
    follows is the one without the grid."""
    entry = oe.snapshot()
    r, ok, _ = oe.residual(start.spec, start.coef)
    own = float(r @ r) if ok else math.inf
    oe.restore(entry)
    grid = baseline_grid_starts(oe, base, ctx)
    if not grid or not grid[0].chi2 < own:
        return None
    best = None
    for g in grid:
        build, params = structure(None, g.spec, ctx)
        oe.restore(({}, {}, list(g.phases)))
        out, ok = oe.refine(g, build, params, max_nfev=max_nfev)
        if best is None or out.chi2 < best[0].chi2:
            best = (out, ok, oe.snapshot(), build, params)
    oe.restore(entry)
    return best


def _off_bound(spec: ModelSpec, coef: np.ndarray, *, rel: float = 1e-3) -> np.ndarray:
    """``coef`` with the contact term moved off its bound: a contact coefficient below ``rel``
    times the lever stiffness ``K`` (the scale of a contact stiffness in units of ``k``) is
    set to that.

    The output-error refinement does not leave a coefficient at its bound 0: its
    finite-difference step is relative to the (scaled) start, so such a coefficient is probed
    by ~1e-10, below the shooting tolerance, and stays switched off. Measured on a strong
    long-range-damping series (damping 8x the lever's, 4 set-points): the baseline ends with
    its contact term at 0, and the damping extension started from the truth's ``a0`` and decay
    length with the contact at 0 ends at chi2 165 with the contact still off and ``a0`` tripled,
    with the contact at 1e-3 at 132 (the generating model refitted: 132).
    """
    out = np.array(coef, float)
    j = spec.term_keys().index("contact")
    out[3 + j] = max(float(out[3 + j]), rel * (abs(float(out[0])) or 1.0))
    return out


def structure(hyp: AbstractHypothesis | None, spec0: ModelSpec, ctx: Context
              ) -> tuple[Build, list[Parameter]]:
    """``build(values) -> spec`` and the parameters ``(a0, *extension)`` around ``spec0``.

    ``a0`` may move by a factor 3 (or the hypothesis' ``a0_factor``) from ``spec0``'s, and
    not above ``ctx.a0_max`` (unless ``spec0``'s already is); with ``ctx.a0_max`` (set-point
    series) it may also move down to the baseline's smallest onset, :data:`A0_MIN_M`; the
    extensions already in ``spec0`` keep their nonlinear parameters (their linear coefficients
    are refitted).

    Why down to :data:`A0_MIN_M`: a conservative model moves the onset out to mimic a loss
    (baselines at 3-11x the drawn ``a0``), and a factor-3 box around it then excludes the
    drawn onset for every extension that could explain the loss (measured on the constructed
    damping series of the tests: baseline ``a0`` 0.20 L_ref, drawn 0.018).
    """
    f = 3.0 if hyp is None else float(hyp.a0_factor)
    hi = spec0.a0 * f
    lo = spec0.a0 / f
    if ctx.a0_max is not None:
        hi = min(hi, max(float(ctx.a0_max), spec0.a0))
        lo = min(lo, max(A0_MIN_M / ctx.length_m, 1e-4))
    params = [Parameter("a0", lo, hi, (), log=True)]
    if hyp is not None:
        params += hyp.parameters(ctx)

    def build(v: Sequence[float]) -> ModelSpec:
        s = spec0.replace(a0=float(v[0]))
        return s if hyp is None else hyp.extend(s, v[1:])

    return build, params


def refine_output_error(oe: OutputError, starts: Sequence[Solution],
                        hyp: AbstractHypothesis | None, base: Solution, ctx: Context, *,
                        max_nfev: int = 25, nested: str = "always", warm: Any = None
                        ) -> tuple[Solution, bool, Build, list[Parameter]]:
    """Output-error refinement from each start; the best refined solution.

    ``hyp`` None refines ``base`` itself. For an extension the nested point (the refined
    base with the extension switched off) is a further start, so the extension, which
    contains the base, cannot end worse than it: refined always (``nested="always"``), or
    only when the other starts end no better than the base (``"fallback"``: saves a
    refinement per cause on joint fits). Returns the solution, whether every orbit
    converged, and the structure (``build``, parameters) it was refined in. ``warm`` (an
    :meth:`OutputError.snapshot`): every start is shot from those orbits, not from the ones
    the start refined before it left (the result then does not depend on the starts' order).
    ``max_nfev`` output-error evaluations per start, at least ``hyp.min_refine_nfev`` where
    the cause sets one.
    """
    build, params = structure(hyp, base.spec, ctx)
    starts = list(starts)
    fallback = None
    if hyp is not None:
        # a cause whose fit needs more evaluations than the caller's budget says so (the JKR
        # neck: ``min_refine_nfev``)
        max_nfev = max(int(max_nfev), hyp.min_refine_nfev)
        nv = hyp.nested_values(params[1:])
        vals = (base.values[0], *nv)
        spec = build(vals)
        fallback = Solution(spec=spec, coef=spec.embed(base.spec, base.coef),
                            residual=base.residual, chi2=base.chi2, values=vals,
                            phases=base.phases)
        if nested == "always":
            starts.append(fallback)
    best: tuple[Solution, bool] | None = None
    entry = oe.snapshot()
    held = None
    if hyp is None and starts:
        held = _grid_refined(oe, starts[0], base, ctx, max_nfev)
    # each refined solution is kept with the orbits it was shot to (``oe.snapshot()``), and
    # ``oe`` is left holding the returned solution's: where two orbits coexist at a set-point
    # the orbits of the last start refined need not lead back to the best one's (measured on
    # a 1,000 spp detector series: re-shot from the last start's orbits, the returned fit
    # 7,333 gave 1.4e6, and its held-out set-points were predicted from the wrong branch)
    best_orbits = entry
    for start in starts:
        _branch(oe, start, warm)
        out, ok = oe.refine(start, build, params, max_nfev=max_nfev)
        if best is None or out.chi2 < best[0].chi2:
            best, best_orbits = (out, ok), oe.snapshot()
    assert best is not None
    if held is not None and held[0].chi2 < best[0].chi2:
        best, best_orbits = (held[0], held[1]), held[2]
        build, params = held[3], held[4]
    if fallback is not None and nested == "fallback" and best[0].chi2 >= base.chi2 - 1e-9:
        # a new coefficient started at 0 sits on its sign bound and least squares does not
        # leave it: also start from the base with the extension's own values and new columns
        # taken from the equation-error start ("mixed"; measured on a hidden-neck series: drop
        # 26.2, the drop at the true neck, against 0.00 from the nested point)
        mixed = [fallback]
        if starts:
            s0 = starts[0]
            vals = (fallback.values[0], *s0.values[1:])
            coef = np.array(fallback.coef, float)
            new_keys = set(fallback.spec.term_keys()) - set(base.spec.term_keys())
            theirs = s0.spec.term_keys()
            signs = fallback.spec.signs()
            for j, key in enumerate(fallback.spec.term_keys()):
                if key in new_keys and key in theirs:
                    coef[3 + j] = s0.coef[3 + theirs.index(key)]
                    if coef[3 + j] == 0.0 and signs[j] != 0:
                        # exactly on its sign bound (the harmonic balance cannot see a neck's
                        # snap): nudged off it (measured: neck drop 0.0 -> 36.1, truth 36.4)
                        coef[3 + j] = signs[j] * 1e-3 * abs(float(fallback.coef[4]))
            mixed.insert(0, Solution(spec=build(vals), coef=coef, residual=base.residual,
                                     chi2=base.chi2, values=vals, phases=base.phases))
        for start in mixed:
            # shot from the orbits held on entry (``warm`` None: the failed start's orbits
            # are no start for the base's point; measured on a dev detector series, seed 9:
            # the mixed start refined 240.5 from the entry orbits, drop 0.00 from those)
            _branch(oe, start, entry if warm is None else warm)
            out, ok = oe.refine(start, build, params, max_nfev=max_nfev)
            if out.chi2 < best[0].chi2:
                best, best_orbits = (out, ok), oe.snapshot()
    if fallback is not None and best[0].chi2 > base.chi2:
        # the extension contains the base: a refinement that ended above it (a lost basin, an
        # orbit that did not converge) is no solution of the extended family; the nested
        # point is (measured on a hidden-neck series: every candidate ended 7e3-1.2e4 above
        # the base with a0 doubled and the contact term gone)
        best, best_orbits = (fallback, True), entry if warm is None else warm
    oe.restore(best_orbits)
    return best[0], best[1], build, params
