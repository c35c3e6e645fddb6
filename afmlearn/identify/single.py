"""The single-orbit fit: one record's force law, as a sequence of stages.

Each stage is a small frozen object with a ``run`` method that takes the immutable
:class:`~afmlearn.identify.single_problem.OrbitProblem` (and what earlier stages returned) and
returns values; no stage keeps state. :func:`fit_orbit` runs them in order (the joint path,
:mod:`afmlearn.identify.joint`, is the same pattern over a ``JointProblem``):

1. :class:`OrbitNoiseScale` - row noise variance from a dense fit (the priors' unit), at the
   first ``a0`` of the grid;
2. :class:`OrbitOnsetProfile` - every ``a0`` of the problem's grid gets its best short model
   (AIC); the best and a bounded refinement between its neighbours;
3. :class:`DrivePhaseChoice` - the drive phase (free fit or a conservative root, by AIC); the
   drive is rotated to it and its amplitude boxed; then :class:`OrbitNoiseScale` again;
4. :class:`OrbitSelection` - SR3 threshold x nu grid (:class:`GridSearch`) plus forward
   selection at the profiled ``a0``; ``a0`` re-profiled for the CV knee's support and the
   selection repeated there when that gains more than 2 AIC units;
5. :class:`ParetoChoice` - every distinct support scored by the held-out orbit error
   (:class:`HeldoutStateError`; and the force error when the truth is given), the knee of the
   Pareto front chosen, AICc as second opinion;
6. :class:`OrbitRefinement` - ``a0``, exponents and decay lengths by Nelder--Mead, accepted
   on a paired rolling-CV gain;
7. the joint path's :class:`~afmlearn.identify.joint.Bagging` - moving-block bootstrap with
   boxes and priors (the same stage: it reads ``design``, ``prior`` and ``blocks`` only);
8. :class:`OrbitExponentProfile` - the dominant ``delta^p``'s residual profile (``a0`` and
   coefficients re-fitted), run on the outputs by the identifier.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from afmlearn.metrics import nrmse
from afmlearn.preprocess import fit_harmonics

from .joint import Bagging
from .library import (
    AFMLibrary,
    Constant,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
    SphereElectrostatic,
)
from .line_search import grid_then_bounded
from .model import IdentifiedModel
from .problem import JointDesign
from .selection import Candidate, GridSearch, best_by_ic, knee_one_se, merge_supports
from .single_problem import N_LIN, OrbitProblem
from .stepwise import ForwardSelection

__all__ = ["DrivePhaseChoice", "HeldoutStateError", "OrbitExponentProfile",
           "OrbitNoiseScale", "OrbitOnsetProfile", "OrbitRefinement", "OrbitResult",
           "OrbitSelection", "ParetoChoice", "Selection", "fit_orbit", "orbit_model",
           "short_models"]

FloatArray = NDArray[np.float64]


# ---------------------------------------------------------------------------- shared pieces
def short_models(problem: OrbitProblem, library: AFMLibrary, a0: float, max_terms: int = 3
                 ) -> tuple[Candidate, float]:
    """Best (by AIC) of the forward-selected supports with up to ``max_terms`` force terms."""
    des = problem.design(library, a0)
    fwd = ForwardSelection(problem.optimizer(des), always=range(N_LIN), max_terms=max_terms,
                           cross_validate=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fwd.fit(des.theta, des.y, problem.blocks, prior=problem.prior(des.theta.shape[1]))
    n = des.y.size
    aic = [n * np.log(max(c.rss, 1e-300) / n) + 2 * c.n_terms for c in fwd.candidates_]
    i = int(np.argmin(aic))
    return fwd.candidates_[i], float(aic[i])


def profile_fixed(problem: OrbitProblem, lib: AFMLibrary, a0: float, n: int = 40) -> float:
    """Least-squares profile of ``a0`` for a fixed support (grid plus bounded refinement)."""
    if not any(t.contact_only for t in lib.terms) and not any(
            isinstance(t, InversePower | SphereElectrostatic) for t in lib.terms):
        return a0
    lo, hi = problem.a0_range

    def rss(a: float) -> float:
        return problem.support_rss(lib, a)

    grid = np.unique(np.concatenate([np.geomspace(lo, hi, n), [a0]]))
    return grid_then_bounded(rss, grid, maxiter=15, xatol=1e-4 * (hi - lo))[0]


def orbit_model(problem: OrbitProblem, library: AFMLibrary, a0: float, coef: FloatArray, *,
                bands: FloatArray | None = None,
                info: dict[str, Any] | None = None) -> IdentifiedModel:
    """The model of coefficients ``coef`` (n_lin + n_terms,) over ``library``'s columns.

    Zero force coefficients are dropped (no term left: an explicit zero constant keeps the
    model valid); ``bands`` (2, n_terms) follow the kept terms. The drive's phase is the
    problem's rotation plus that of the fitted ``(B_c, B_s)``.
    """
    cal = problem.calibrated
    keep = np.asarray(coef[N_LIN:]) != 0
    lib = library.subset(keep) if keep.any() else None
    cf = np.asarray(coef[N_LIN:])[keep]
    if lib is None:
        lib, cf = AFMLibrary([Constant()]), np.zeros(1)
        bands = None
    elif bands is not None:
        bands = bands[:, keep]
    bc, bs = float(coef[2]), float(coef[3])
    amp = math.hypot(bc, bs)
    phase = problem.rotation + math.atan2(bs, bc)
    g = cal.gap if np.isscalar(cal.gap) else float(np.mean(cal.gap))
    return IdentifiedModel(library=lib, coefficients=cf, stiffness=-float(coef[1]),
                           damping=-float(coef[0]), drive_amplitude=amp,
                           drive_phase=phase, omega=cal.omega, a0=float(a0),
                           gap=float(g), scales=cal.scales, coefficient_bands=bands,
                           info=info or {})


# ---------------------------------------------------------------------------- stages
@final
@dataclass(frozen=True)
class OrbitNoiseScale:
    """Row noise variance from a dense box-constrained fit (no threshold, no prior) at
    ``(library, a0)``; returns the problem with it (:meth:`OrbitProblem.with_noise`)."""

    def run(self, problem: OrbitProblem, library: AFMLibrary, a0: float) -> OrbitProblem:
        des = problem.design(library, a0)
        p = des.theta.shape[1]
        G = des.theta.T @ des.theta
        c = problem.optimizer(des).refit_gram(G, des.theta.T @ des.y, np.ones(p, bool))[0]
        r = des.y - des.theta @ c
        dof = max(des.theta.shape[0] - p, 1)
        return problem.with_noise(float(r @ r / dof) or 1e-30)


@final
@dataclass(frozen=True)
class OrbitOnsetProfile:
    """Best short-model AIC at every ``a0`` of the problem's grid.

    Returns the best ``a0`` (grid, then a bounded refinement between its neighbours when it
    is inside) and the profile ``(a0, AIC)``, shape (n_grid, 2).
    """

    max_terms: int = 3

    def run(self, problem: OrbitProblem, library: AFMLibrary) -> tuple[float, FloatArray]:
        grid = problem.a0_grid

        def objective(a: float) -> float:
            return short_models(problem, library, float(a), self.max_terms)[1]

        best, _, vals = grid_then_bounded(objective, grid, maxiter=10,
                                          xatol=1e-4 * problem.orbit_span)
        return best, np.column_stack([grid, vals])


def _conservative_phases(problem: OrbitProblem, fc: float) -> list[float]:
    """Drive phases of the two conservative roots of the fundamental's balance."""
    cal = problem.calibrated
    om = cal.omega
    x1 = complex(fit_harmonics(problem.tau_fit, problem.denoised.x, om,
                               n_harmonics=1).complex_amplitudes[1])
    if abs(x1) == 0:
        return []
    dd = om / cal.quality_factor
    rad = math.sqrt(max((fc / abs(x1)) ** 2 - dd**2, 0.0))
    out = []
    for re in (rad, -rad):  # re = K + s - Omega^2
        e = complex(re, dd) * x1 / fc  # = e^{-i phi}
        out.append(float(-math.atan2(e.imag, e.real)))
    return out


@final
@dataclass(frozen=True)
class DrivePhaseChoice:
    """Drive phase: the best of a few candidate phases with the drive amplitude boxed.

    The fundamental's balance is ``(K - Omega^2 + i Omega D) X_1 + F_1 = B e^{-i phi}``.
    With a free drive (amplitude and phase) these two equations are absorbed by the drive,
    so a free fit sets ``phi`` only through the force's other harmonics; when those are
    below the noise (small, nearly linear orbits) ``phi`` is undetermined and the free
    fit can land on the mirror branch (force gradient of the wrong sign, the drive phase
    flipped by ~pi). The calibrated amplitude ``|B| = F_c`` removes that freedom: a
    conservative ``F_1 = s X_1`` must satisfy ``|K + s - Omega^2 + i Omega D| =
    F_c / |X_1|``, two roots ``s``. The candidates are the free fit's phase and the two
    roots' phases; for each, the best short model is selected with the drive rotated to
    it and boxed (amplitude and quadrature within the drive tolerance), and the lowest
    AIC wins; within 2 AIC units of the best the roots are preferred. The phase is not
    refined further by least squares: a drive quadrature error trades against dissipative
    terms (the fundamental's quadrature balance), so a free phase would buy fake
    dissipation; the box leaves +-tolerance of quadrature. Without a calibrated drive the
    free fit's phase is used and the drive stays free.

    ``run`` takes a problem whose drive is free and returns the rotated problem and the
    scored candidates ``[(phi, AIC), ...]`` (empty without a calibrated drive).
    """

    max_terms: int = 3

    def run(self, problem: OrbitProblem, library: AFMLibrary, a0: float
            ) -> tuple[OrbitProblem, list[tuple[float, float]]]:
        best, _ = short_models(problem, library, a0, self.max_terms)
        c = best.coef[0]
        phi_free = float(math.atan2(c[3], c[2]))
        fc = problem.calibrated.drive_amplitude
        if fc is None:
            return problem.with_drive(phi_free, rotated=False), []
        cands = [phi_free, *_conservative_phases(problem, fc)]
        distinct: list[float] = []
        for phi in cands:
            if all(abs(math.remainder(phi - d, 2 * math.pi)) > 0.02 for d in distinct):
                distinct.append(phi)
        scored = [(short_models(problem.with_drive(phi, rotated=True), library, a0,
                                self.max_terms)[1], phi) for phi in distinct]
        # the conservative roots are exact for conservative forces; within 2 AIC units
        # (no evidence either way) prefer them: a free phase buys fake dissipation
        best_aic = min(a for a, _ in scored)
        roots = [t for t in scored[1:] if t[0] <= best_aic + 2.0] if len(distinct) > 1 \
            and distinct[0] == phi_free else []
        _, phi = min(roots or scored, key=lambda t: t[0])
        return (problem.with_drive(phi, rotated=True),
                [(float(p), float(a)) for a, p in scored])


@final
@dataclass(frozen=True, eq=False)
class Selection:
    """What :class:`OrbitSelection` found (immutable).

    Attributes
    ----------
    design : JointDesign
        Rows of the full library at the selection's ``a0`` (``design.a0``).
    search : GridSearch
        The fitted threshold x nu grid.
    candidates : list of Candidate
        Distinct supports of the grid and the forward path (columns of ``design``).
    """

    design: JointDesign
    search: GridSearch
    candidates: list[Candidate]


@final
@dataclass(frozen=True)
class OrbitSelection:
    """SR3 threshold x nu grid plus forward selection, alternating once with ``a0``.

    A support is selected at the profiled ``a0``; ``a0`` is re-profiled (least squares) for
    the CV knee's support (the profile's short models may prefer another contact onset) and
    the selection is repeated there when the move gains more than 2 AIC units (``a0`` is one
    more fitted parameter).
    """

    n_folds: int = 10
    max_terms: int = 6

    def _select(self, problem: OrbitProblem, library: AFMLibrary, a0: float) -> Selection:
        des = problem.design(library, a0)
        theta_p, y_p = problem.prior_rows(des)
        search = GridSearch(problem.optimizer(des), problem.thresholds, problem.nus,
                            n_folds=self.n_folds)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            search.fit(theta_p, y_p)
        fwd = ForwardSelection(problem.optimizer(des), always=range(N_LIN),
                               max_terms=self.max_terms).fit(
            des.theta, des.y, problem.blocks, prior=problem.prior(des.theta.shape[1]))
        return Selection(design=des, search=search,
                         candidates=merge_supports(search.candidates_, fwd.candidates_))

    def run(self, problem: OrbitProblem, library: AFMLibrary, a0: float,
            log: Callable[[str], None] | None = None) -> Selection:
        sel = self._select(problem, library, a0)
        des, cands = sel.design, sel.candidates
        first = cands[knee_one_se(cands, ("cv_error",))]
        keep = first.coef[0][N_LIN:] != 0
        a0_new, aic_gain = a0, 0.0
        if keep.any():
            lib_first = des.library.subset(keep)
            a0_new = profile_fixed(problem, lib_first, a0)
            r0 = problem.support_rss(lib_first, a0)
            r1 = problem.support_rss(lib_first, a0_new)
            aic_gain = des.y.size * math.log(max(r1, 1e-300) / max(r0, 1e-300))
        if abs(a0_new - a0) > 1e-3 * problem.orbit_span and aic_gain < -2.0:
            if log is not None:
                log(f"a0 {a0:.4g} -> {a0_new:.4g} for the chosen support; reselecting")
            sel = self._select(problem, library, a0_new)
        return sel


@final
@dataclass(frozen=True)
class HeldoutStateError:
    """Held-out orbit error: mean NRMSE of ``x``, ``x'``, ``x''`` (design.md section 4).

    The model is simulated from the measured (denoised) state at the start of the held-out
    span; the reference ``x``, ``x'``, ``x''`` come from denoising the held-out samples on
    their own (never used in fitting), so measurement noise does not set a floor.

    Parameters
    ----------
    max_heldout_periods : float
        Longest simulated held-out span.
    substeps : int or None
        RK4 steps per sample (None: at least 400 steps per drive period).
    """

    max_heldout_periods: float = 60.0
    substeps: int | None = None

    def run(self, problem: OrbitProblem, model: IdentifiedModel) -> float:
        cal = problem.calibrated
        i0 = problem.heldout_start
        n_h = min(cal.n_samples - i0, int(self.max_heldout_periods * cal.samples_per_period))
        x0, v0 = problem.initial_state(i0)
        dtau = float(cal.tau[1] - cal.tau[0])
        sub = self.substeps or max(1, math.ceil(400 / cal.samples_per_period))
        xs, vs = model.simulate(x0, v0, tau0=float(cal.tau[i0]), dtau=dtau, n_samples=n_h,
                                substeps=sub)
        if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(vs))):
            return 1.0
        tau = cal.tau[i0:i0 + n_h]
        gap = np.broadcast_to(np.asarray(cal.gap, float), cal.tau.shape)[i0:i0 + n_h]
        acc = (-model.damping * vs - model.stiffness * xs
               + model.drive_amplitude * np.cos(model.omega * tau - model.drive_phase)
               - model.force(gap - xs, -vs, xs))
        errs = [nrmse(a, b[:n_h])
                for a, b in zip((xs, vs, acc), problem.heldout_reference, strict=True)]
        return float(min(np.mean(errs), 1.0))


def force_error(problem: OrbitProblem, model: IdentifiedModel, f_true: FloatArray) -> float:
    """NRMSE of the model's force on the training span's denoised orbit against the truth
    ``f_true`` (heldout_start,)."""
    d = problem.denoised
    f = model.force(np.asarray(problem.gap_fit - d.x, float), -d.v, d.x)
    return float(nrmse(f, f_true))


@final
@dataclass(frozen=True)
class ParetoChoice:
    """Score every candidate, pick the knee of the Pareto front and the AICc choice.

    The rolling-CV error of the projected equation is the sharpest out-of-sample signal; the
    held-out simulated orbit (``state``) and, in training, the force error complete the front.

    Returns the scored candidates (copies with ``scores`` filled in), the objectives, the
    knee's index and the AICc choice's index.
    """

    state: HeldoutStateError = HeldoutStateError()

    def run(self, problem: OrbitProblem, sel: Selection, true_force: FloatArray | None
            ) -> tuple[list[Candidate], tuple[str, ...], int, int]:
        des = sel.design
        cands = []
        for c in sel.candidates:
            m = orbit_model(problem, des.library, des.a0, c.coef[0])
            scores = {**c.scores, "state_error": self.state.run(problem, m)}
            if true_force is not None:
                scores["force_error"] = force_error(problem, m,
                                                    true_force[:problem.heldout_start])
            cands.append(dataclasses.replace(c, scores=scores))
        objectives = (("cv_error", "state_error", "force_error") if true_force is not None
                      else ("cv_error", "state_error"))
        return cands, objectives, knee_one_se(cands, objectives), best_by_ic(cands, "aicc")


@final
@dataclass(frozen=True)
class OrbitRefinement:
    """``a0``, exponents and decay lengths of a fixed support by Nelder--Mead on the
    constrained least-squares residual; accepted only on an out-of-sample gain (paired over
    the CV folds): along the flat valleys of (a0, exponent, stiffness) the residual alone
    wanders to the bounds.

    Exponents stay in [0.5, 4] within ``max_exponent_step`` of their start, decay lengths in
    [1e-3, 2], ``a0`` in the problem's range. Returns ``(library, a0, refined)``.
    """

    max_exponent_step: float = 0.5

    def _minimise(self, problem: OrbitProblem, lib: AFMLibrary, a0: float
                  ) -> tuple[AFMLibrary, float]:
        params: list[tuple[int, str, float]] = [(-1, "a0", a0)]
        for j, t in enumerate(lib.terms):
            if isinstance(t, Indentation | IndentationRate):
                params.append((j, "p", t.p))
            elif isinstance(t, ExponentialDamping):
                params.append((j, "decay_length", t.decay_length))
        x0 = np.array([v for _, _, v in params], float)
        lo_a, hi_a = problem.a0_range

        def build(v: FloatArray) -> tuple[AFMLibrary, float] | None:
            new = lib
            for (j, name, _), val in zip(params[1:], v[1:], strict=True):
                if name == "p":
                    p0 = lib.terms[j].p
                    if not (0.5 <= val <= 4.0 and abs(val - p0) <= self.max_exponent_step):
                        return None
                    t = lib.terms[j]
                    new = new.replace(j, type(t)(float(val)) if isinstance(t, Indentation)
                                      else IndentationRate(float(val), t.l))
                else:
                    if not 1e-3 <= val <= 2.0:
                        return None
                    new = new.replace(j, ExponentialDamping(float(val)))
            if not (v[0] > 0 and lo_a <= v[0] <= hi_a):
                return None
            return new, float(v[0])

        def obj(v: FloatArray) -> float:
            built = build(v)
            if built is None:
                return 1e300
            des = problem.design(*built)
            G, b = problem.gram(des)
            try:
                c = problem.optimizer(des).refit_gram(G, b, np.ones(G.shape[0], bool))[0]
            except (ValueError, np.linalg.LinAlgError):  # infeasible corner of the search
                return 1e300
            r = des.y - des.theta @ c
            return float(r @ r)

        step = np.where(x0 != 0, 0.05 * np.abs(x0), 0.01)
        simplex = np.vstack([x0] + [x0 + np.eye(x0.size)[i] * step[i] for i in range(x0.size)])
        res = minimize(obj, x0, method="Nelder-Mead",
                       options={"initial_simplex": simplex, "xatol": 1e-4, "fatol": 1e-12,
                                "maxiter": 200 * x0.size})
        best = build(res.x) if res.fun <= obj(x0) else None
        return best if best is not None else (lib, a0)

    def run(self, problem: OrbitProblem, lib: AFMLibrary, a0: float
            ) -> tuple[AFMLibrary, float, bool]:
        lib_r, a0_r = self._minimise(problem, lib, a0)
        e0 = problem.cv(lib, a0)
        e1 = problem.cv(lib_r, a0_r)
        d = e1 - e0
        if (np.all(np.isfinite(d)) and d.size > 1
                and float(d.mean()) < -float(d.std(ddof=1)) / np.sqrt(d.size)):
            return lib_r, a0_r, True
        return lib, a0, False


@final
@dataclass(frozen=True)
class OrbitExponentProfile:
    """Profile residual of the interaction exponent, shape (n_p, 2): ``(p, min RSS)``.

    The term ``delta^p0`` of the support is swept over ``p`` in ``low ... high`` (``step``)
    with the other terms kept; ``a0`` and all coefficients are re-fitted at every ``p``
    (``a0`` on ``n_a0`` geometric points over its range plus the model's), so the profile
    follows the (a0, exponent, stiffness) valley. ``run`` returns None when the support has
    no ``delta^p0`` term.
    """

    low: float = 0.5
    high: float = 4.0
    step: float = 0.25
    n_a0: int = 10

    def run(self, problem: OrbitProblem, lib: AFMLibrary, a0: float, p0: float | None
            ) -> FloatArray | None:
        js = [j for j, t in enumerate(lib.terms)
              if isinstance(t, Indentation) and p0 is not None and t.p == p0]
        if not js:
            return None
        j = js[0]
        lo, hi = problem.a0_range
        a0s = np.unique(np.concatenate([np.geomspace(lo, hi, self.n_a0), [a0]]))
        ps = np.unique(np.concatenate([np.arange(self.low, self.high + 0.001, self.step),
                                       [p0]]))
        out = []
        for p in ps:
            lp = lib.replace(j, Indentation(float(p)))
            out.append((float(p), min(problem.support_rss(lp, a) for a in a0s)))
        return np.array(out)


# ---------------------------------------------------------------------------- pipeline
@final
@dataclass(frozen=True, eq=False)
class OrbitResult:
    """What :func:`fit_orbit` found (immutable).

    Attributes
    ----------
    problem : OrbitProblem
        With the drive rotation and noise variance of the final fit.
    library : AFMLibrary
        The chosen support's force terms (refined exponents): the columns of ``coef``.
    a0 : float
    coef : ndarray, shape (n_lin + n_terms,)
        Final coefficients ``[-D, -K, B_c, B_s, c_j...]`` (drive in the rotated frame).
    samples : ndarray, shape (n_boot, n_lin + n_terms), or None
        Bootstrap coefficients (None without bagging).
    selection : Selection
    candidates : list of Candidate
        Scored distinct supports (columns of ``selection.design``).
    objectives : tuple of str
    knee_index, ic_index : int
    a0_profile : ndarray, shape (n_grid, 2)
    drive_phase_candidates : list of (float, float)
        ``(phi, AIC)`` of the drive phases considered.
    refined : bool
    """

    problem: OrbitProblem
    library: AFMLibrary
    a0: float
    coef: FloatArray
    samples: FloatArray | None
    selection: Selection
    candidates: list[Candidate]
    objectives: tuple[str, ...]
    knee_index: int
    ic_index: int
    a0_profile: FloatArray
    drive_phase_candidates: list[tuple[float, float]]
    refined: bool

    @property
    def chosen(self) -> Candidate:
        return self.candidates[self.knee_index]


def fit_orbit(problem: OrbitProblem, library: AFMLibrary, *,
              onset: OrbitOnsetProfile | None = None,
              drive: DrivePhaseChoice | None = None,
              selection: OrbitSelection | None = None,
              choice: ParetoChoice | None = None,
              refinement: OrbitRefinement | None = None,
              bagging: Bagging | None = None,
              true_force: FloatArray | None = None,
              log: Callable[[str], None] | None = None) -> OrbitResult:
    """Run the stages (module docstring) on ``problem`` with candidate terms ``library``.

    ``refinement`` None skips the refinement, ``bagging`` None the bootstrap; ``true_force``
    (n,) [k L_ref] adds the force error to the Pareto front (training on simulations).
    """
    def say(msg: str) -> None:
        if log is not None:
            log(msg)

    say("a0 profile")
    problem = OrbitNoiseScale().run(problem, library, float(problem.a0_grid[0]))
    a0, a0_prof = (onset or OrbitOnsetProfile()).run(problem, library)
    problem, phases = (drive or DrivePhaseChoice()).run(problem, library, a0)
    problem = OrbitNoiseScale().run(problem, library, a0)
    say("model selection")
    sel = (selection or OrbitSelection()).run(problem, library, a0, log=log)
    say(f"scoring {len(sel.candidates)} candidate supports")
    cands, objectives, ki, ii = (choice or ParetoChoice()).run(problem, sel, true_force)
    des = sel.design
    lib_s = des.library.subset(cands[ki].coef[0][N_LIN:] != 0)
    a0_s, refined = des.a0, False
    if refinement is not None and lib_s.n_terms:
        say("refining a0 and exponents")
        lib_s, a0_s, refined = refinement.run(problem, lib_s, a0_s)
    des_f = problem.design(lib_s, a0_s)
    coef = problem.refit(des_f, np.ones(des_f.theta.shape[1], bool))
    samples = None if bagging is None else bagging.run(problem, des_f)  # type: ignore[arg-type]
    return OrbitResult(problem=problem, library=lib_s, a0=a0_s, coef=coef, samples=samples,
                       selection=sel, candidates=cands, objectives=objectives,
                       knee_index=ki, ic_index=ii, a0_profile=a0_prof,
                       drive_phase_candidates=phases, refined=refined)
