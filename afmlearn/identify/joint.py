"""The joint fit: one force law across every observation, as a sequence of stages.

Each stage is a small frozen object with a ``run`` method that takes the immutable
:class:`~afmlearn.identify.problem.JointProblem` (and what earlier stages returned) and
returns values; no stage keeps state. :func:`fit_joint` runs them in order:

1. the drive strategy rotates recorded phases in (:mod:`afmlearn.identify.drive`);
2. :class:`NoiseScale` - the variance of a whitened row from a dense fit (priors' unit);
3. :class:`ContactOnsetProfile` - ``a0`` on a grid, each with its best short model (AIC);
4. :func:`estimate_phases` - observations without a recorded phase get theirs (the free
   fit's phase or the nearer conservative root, by AIC) and a boxed drive;
5. :class:`SupportSelection` - forward selection with rolling cross-validation over the joint
   blocks, the one-standard-error knee on the CV error (AICc as second opinion), ``a0``
   re-profiled for the chosen support;
   then :class:`OrbitOffsets` - each observation's gap offset (the denoised orbit's error
   at its turning point, under its prior) for the chosen law, and the selection again;
6. :class:`Refinement` - ``a0`` and exponents by Nelder--Mead, accepted on a paired CV gain;
7. :class:`Bagging` - block bootstrap for coefficient bands;
8. with an :class:`~afmlearn.identify.output_error.OutputErrorStage`: the law's own
   periodic orbits (one compiled kernel, Newton shooting) against every observation's
   measured harmonics; the shared law, the drive phases and the support are refined on that
   objective and the exponent's profile likelihood comes from it (the equation-error rows
   evaluate the force on denoised orbits whose error near the turning point differs per
   set-point, which biased the exponent); its Gauss--Newton covariance gives the bands.
   Without it (or when its orbits are not found): :class:`Bagging` - block bootstrap for
   coefficient bands, and :class:`ExponentProfile` - the contact exponent's profile likelihood
   over the JOINT equation-error fit (``a0`` and every coefficient re-fitted at each
   exponent), its 95 % interval and whether the data bound it.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize, minimize_scalar

from .drive import AbstractDrivePhase, RecordedPhase
from .library import AFMLibrary, ExponentialDamping, Indentation, IndentationRate, InversePower
from .line_search import grid_then_bounded
from .output_error import OutputErrorResult, OutputErrorStage, covariance_samples
from .problem import JointDesign, JointProblem
from .selection import Candidate, best_by_ic, knee_one_se, profile_interval
from .stepwise import ForwardSelection, cv_errors

__all__ = ["Bagging", "ContactOnsetProfile", "ExponentProfile", "JointResult", "NoiseScale",
           "OrbitOffsets", "Refinement", "SupportSelection", "estimate_phases", "fit_joint",
           "fit_offsets", "block_mean_rss", "support_fit"]

FloatArray = NDArray[np.float64]

#: the output-error stage :func:`fit_joint` runs unless told otherwise
DEFAULT_OUTPUT_ERROR = OutputErrorStage()


# ---------------------------------------------------------------------------- shared pieces
def support_fit(problem: JointProblem, library: AFMLibrary, a0: float
                ) -> tuple[FloatArray, float, JointDesign]:
    """Coefficients (p,), data RSS and design of the full support of ``library`` at ``a0``.

    RSS is ``inf`` when the boxes cannot be met.
    """
    des = problem.design(library, a0, pattern=False)
    G0, b0 = problem.prior(des.theta.shape[1])
    G = des.theta.T @ des.theta + G0
    b = des.theta.T @ des.y + b0
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c = des.optimizer().refit_gram(G, b, np.ones(G.shape[0], bool))[0]
    except (ValueError, np.linalg.LinAlgError):  # an infeasible corner of a search
        return np.full(des.theta.shape[1], np.nan), math.inf, des
    r = des.y - des.theta @ c
    return c, float(r @ r) + problem.offset_penalty(), des


def block_mean_rss(problem: JointProblem, des: JointDesign, coef: FloatArray
                   ) -> tuple[float, int]:
    """RSS of the block-averaged residual rows (plus the offsets' prior) and their number.

    Every block of an observation repeats its force columns, so a misfit of the law (or of
    the denoised orbit it is evaluated on) recurs identically in every block while the noise
    averages down; the profile likelihood on the block means therefore takes the misfit at
    its real weight (a quasi-likelihood whose dispersion includes it) instead of counting it
    ``n_blocks`` times, which made a wrong law look certain.
    """
    r = des.y - des.theta @ coef
    idx = problem.block_mean_index
    m = np.bincount(idx, weights=r) / problem.n_blocks
    return (float(m @ m) + problem.offset_penalty() / problem.n_blocks**2, int(m.size))


def fit_offsets(problem: JointProblem, library: AFMLibrary, a0: float, coef: FloatArray
                ) -> JointProblem:
    """Each observation's gap offset for the given law (coefficients held), with its prior.

    Observation ``i`` minimises ``|r_i(delta)|^2 + s2 (delta / orbit_sigma_i)^2`` over
    ``|delta| <= 5 orbit_sigma_i`` (bounded scalar search); the observations are independent
    given the shared coefficients.
    """
    if not library.n_terms or not np.all(np.isfinite(coef)):
        return problem
    n_lin = problem.n_lin
    c_lin, c_f = coef[:n_lin], coef[n_lin:]
    out = np.array(problem.offsets, float)
    for i, o in enumerate(problem.observations):
        s = o.orbit_sigma
        y, lin, _ = problem.observation_rows(i, library, a0, 0.0)
        base = y - lin @ c_lin

        def cost(d: float, i: int = i, base: FloatArray = base, s: float = s) -> float:
            f = problem.observation_rows(i, library, a0, d)[2]
            r = base + f @ c_f
            return float(r @ r) + problem.noise_scale * (d / s) ** 2

        res = minimize_scalar(cost, bounds=(-5 * s, 5 * s), method="bounded",
                              options={"xatol": 0.05 * s, "maxiter": 12})
        out[i] = float(res.x) if res.fun <= cost(float(out[i])) else out[i]
    return problem.with_offsets(out)


@final
@dataclass(frozen=True)
class OrbitOffsets:
    """Alternate the shared law's refit with every observation's gap offset (``rounds``)."""

    rounds: int = 2

    def run(self, problem: JointProblem, library: AFMLibrary, a0: float) -> JointProblem:
        for _ in range(self.rounds):
            coef = support_fit(problem, library, a0)[0]
            problem = fit_offsets(problem, library, a0, coef)
        return problem


def short_model(problem: JointProblem, library: AFMLibrary, a0: float, max_terms: int = 3
                ) -> tuple[Candidate, float]:
    """Best (by AIC) forward-selected support with up to ``max_terms`` force terms."""
    des = problem.design(library, a0)
    # greedy (exhaustive=1): the profile only needs the objective's shape along a0; pairs
    # of the 30-term library cost ~6x more for the same choice of a0
    fwd = ForwardSelection(des.optimizer(), always=range(problem.n_lin), max_terms=max_terms,
                           cross_validate=False, exhaustive=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fwd.fit(des.theta, des.y, problem.blocks, prior=problem.prior(des.theta.shape[1]))
    n = des.y.size
    aic = [n * math.log(max(c.rss, 1e-300) / n) + 2 * c.n_terms for c in fwd.candidates_]
    i = int(np.argmin(aic))
    return fwd.candidates_[i], float(aic[i])


def _knee(cands: list[Candidate]) -> int:
    """Sparsest candidate within one paired standard error (or 1 % per dropped term) of
    every denser one on the CV error (``selection.knee_one_se``)."""
    return knee_one_se(cands, ("cv_error",))


# ---------------------------------------------------------------------------- stages
@final
@dataclass(frozen=True)
class NoiseScale:
    """Variance of a whitened row from a dense box-constrained fit (no threshold, no prior)."""

    def run(self, problem: JointProblem, library: AFMLibrary) -> JointProblem:
        a0 = math.sqrt(problem.a0_range[0] * problem.a0_range[1])
        des = problem.design(library, a0)
        G = des.theta.T @ des.theta
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                c = des.optimizer().refit_gram(G, des.theta.T @ des.y,
                                               np.ones(G.shape[0], bool))[0]
        except (ValueError, np.linalg.LinAlgError):  # keep the analytic whitening
            return problem
        r = des.y - des.theta @ c
        dof = max(des.y.size - G.shape[0], 1)
        return problem.with_noise(float(r @ r) / dof)


@final
@dataclass(frozen=True)
class ContactOnsetProfile:
    """``a0`` on a geometric grid over the allowed range, each with its best short model.

    Returns the best ``a0`` (grid, then a bounded refinement between its neighbours) and the
    profile ``(a0, AIC)`` of shape (n_a0, 2).
    """

    n_a0: int = 10
    max_terms: int = 3

    def run(self, problem: JointProblem, library: AFMLibrary) -> tuple[float, FloatArray]:
        lo, hi = problem.a0_range
        grid = np.geomspace(lo, hi, self.n_a0)
        best, _, vals = grid_then_bounded(
            lambda a: short_model(problem, library, a, self.max_terms)[1], grid, maxiter=5)
        return best, np.column_stack([grid, vals])


def _conservative_phase(problem: JointProblem, i: int, near: float) -> float | None:
    """Phase of the conservative root of observation ``i``'s fundamental nearest ``near``.

    ``|K + s - Omega^2 + i Omega D| = F_c / |X_1|`` for a force gradient ``s``: two roots.
    """
    o = problem.observations[i]
    fc = o.drive_amplitude
    x1 = complex(o.harmonic_fit.complex_amplitudes[1])
    if fc is None or abs(x1) == 0:
        return None
    dd = o.omega / problem.quality_factor
    rad = math.sqrt(max((fc / abs(x1)) ** 2 - dd**2, 0.0))
    roots = []
    for re in (rad, -rad):
        e = complex(re, dd) * x1 / fc  # = e^{-i phi}
        roots.append(float(-math.atan2(e.imag, e.real)))
    return min(roots, key=lambda p: abs(math.remainder(p - near, 2 * math.pi)))


def estimate_phases(problem: JointProblem, library: AFMLibrary, a0: float, *,
                    max_terms: int = 3) -> tuple[JointProblem, dict[str, Any]]:
    """Rotate and box the drive of every observation whose phase is still free.

    Candidates: the phase of the free fit (best short model at ``a0``) and, per observation,
    the conservative root nearest to it. The roots win unless the free phases are better by
    more than 2 AIC units (a free phase buys fake dissipation through the quadrature balance).
    """
    free = ~problem.rotated
    if not free.any():
        return problem, {"method": "recorded"}
    cand, _ = short_model(problem, library, a0, max_terms)
    c = cand.coef[0]
    j = problem.n_lin - 2 * int(free.sum())
    phi_free = np.array(problem.rotations, float)
    for i in np.flatnonzero(free):
        phi_free[i] = math.atan2(c[j + 1], c[j])
        j += 2
    widths = np.array(problem.phase_widths, float)
    options = {"free": phi_free}
    if problem.drive_amplitude is not None:
        roots = phi_free.copy()
        for i in np.flatnonzero(free):
            r = _conservative_phase(problem, int(i), float(phi_free[i]))
            roots[i] = phi_free[i] if r is None else r
        options["roots"] = roots
    scored = {k: short_model(problem.with_drive(v, widths), library, a0, max_terms)[1]
              for k, v in options.items()}
    pick = ("roots" if "roots" in scored and scored["roots"] <= scored["free"] + 2.0
            else "free")
    return (problem.with_drive(options[pick], widths),
            {"method": pick, "aic": scored, "phases": options[pick].tolist()})


@final
@dataclass(frozen=True)
class SupportSelection:
    """Forward selection with rolling CV over the joint blocks; the knee; ``a0`` re-profiled.

    Returns the design, the candidates, the knee and AICc indices and the final ``a0``.
    """

    max_terms: int = 6
    n_a0: int = 24

    def _select(self, problem: JointProblem, library: AFMLibrary, a0: float
                ) -> tuple[JointDesign, list[Candidate]]:
        des = problem.design(library, a0)
        fwd = ForwardSelection(des.optimizer(), always=range(problem.n_lin),
                               max_terms=self.max_terms)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fwd.fit(des.theta, des.y, problem.blocks, prior=problem.prior(des.theta.shape[1]))
        return des, list(fwd.candidates_)

    def run(self, problem: JointProblem, library: AFMLibrary, a0: float
            ) -> tuple[JointDesign, list[Candidate], int, int]:
        des, cands = self._select(problem, library, a0)
        ki = _knee(cands)
        keep = cands[ki].coef[0][problem.n_lin:] != 0
        if keep.any():
            lib_k = library.subset(keep)
            lo, hi = problem.a0_range
            grid = np.unique(np.concatenate([np.geomspace(lo, hi, self.n_a0), [a0]]))
            rss = np.array([support_fit(problem, lib_k, float(a))[1] for a in grid])
            a_new = float(grid[int(np.argmin(rss))])
            r0 = support_fit(problem, lib_k, a0)[1]
            gain = des.y.size * math.log(max(float(rss.min()), 1e-300) / max(r0, 1e-300))
            if abs(a_new - a0) > 1e-3 * (hi - lo) and gain < -2.0:
                des, cands = self._select(problem, library, a_new)
                ki = _knee(cands)
        return des, cands, ki, best_by_ic(cands, "aicc")


def _exponent_params(lib: AFMLibrary) -> list[tuple[int, str, float]]:
    out: list[tuple[int, str, float]] = []
    for j, t in enumerate(lib.terms):
        if isinstance(t, Indentation | IndentationRate):
            out.append((j, "p", float(t.p)))
        elif isinstance(t, ExponentialDamping):
            out.append((j, "decay_length", float(t.decay_length)))
    return out


def _rebuild(lib: AFMLibrary, params: list[tuple[int, str, float]], values: FloatArray
             ) -> AFMLibrary | None:
    new = lib
    for (j, name, v0), val in zip(params, values, strict=True):
        t = lib.terms[j]
        if name == "p":
            if not (0.5 <= val <= 4.0 and abs(val - v0) <= 0.75):
                return None
            new = new.replace(j, Indentation(float(val)) if isinstance(t, Indentation)
                              else IndentationRate(float(val), t.l))
        else:
            if not 1e-3 <= val <= 2.0:
                return None
            new = new.replace(j, ExponentialDamping(float(val)))
    return new


@final
@dataclass(frozen=True)
class Refinement:
    """``a0``, exponents and decay lengths of a fixed support by Nelder--Mead on the joint RSS;
    accepted only on a paired rolling-CV gain (one standard error)."""

    max_iter: int = 300

    def run(self, problem: JointProblem, lib: AFMLibrary, a0: float
            ) -> tuple[AFMLibrary, float, bool]:
        params = _exponent_params(lib)
        lo, hi = problem.a0_range
        x0 = np.array([math.log(a0), *[v for _, _, v in params]], float)

        def build(v: FloatArray) -> tuple[AFMLibrary, float] | None:
            a = math.exp(float(v[0]))
            if not lo <= a <= hi:
                return None
            new = _rebuild(lib, params, v[1:])
            return None if new is None else (new, a)

        def obj(v: FloatArray) -> float:
            b = build(v)
            return 1e300 if b is None else support_fit(problem, *b)[1]

        step = np.array([0.1, *[0.05 * max(abs(v), 0.1) for _, _, v in params]])
        simplex = np.vstack([x0] + [x0 + np.eye(x0.size)[i] * step[i] for i in range(x0.size)])
        res = minimize(obj, x0, method="Nelder-Mead",
                       options={"initial_simplex": simplex, "xatol": 1e-4, "fatol": 1e-10,
                                "maxiter": self.max_iter})
        built = build(res.x) if res.fun < obj(x0) else None
        if built is None:
            return lib, a0, False
        e0 = _cv(problem, lib, a0)
        e1 = _cv(problem, *built)
        d = e1 - e0
        if (np.all(np.isfinite(d)) and d.size > 1
                and float(d.mean()) < -float(d.std(ddof=1)) / math.sqrt(d.size)):
            return built[0], built[1], True
        return lib, a0, False


def _cv(problem: JointProblem, lib: AFMLibrary, a0: float) -> FloatArray:
    des = problem.design(lib, a0)
    supp = np.ones(des.theta.shape[1], bool)
    return cv_errors(des.optimizer(), des.theta, des.y, problem.blocks, supp,
                     prior=problem.prior(des.theta.shape[1]))


@final
@dataclass(frozen=True)
class Bagging:
    """Moving-block bootstrap over the joint blocks; boxes and priors kept in every refit."""

    n_bootstrap: int = 40
    seed: int = 0

    def run(self, problem: JointProblem, des: JointDesign) -> FloatArray:
        if self.n_bootstrap <= 0:
            return np.empty((0, des.theta.shape[1]))
        rng = np.random.default_rng(self.seed)
        blocks = problem.blocks
        nb = len(blocks)
        G0, b0 = problem.prior(des.theta.shape[1])
        Gb = [des.theta[a:z].T @ des.theta[a:z] for a, z in blocks]
        bb = [des.theta[a:z].T @ des.y[a:z] for a, z in blocks]
        supp = np.ones(des.theta.shape[1], bool)
        opt = des.optimizer()
        out = []
        for _ in range(self.n_bootstrap):
            pick = rng.integers(0, nb, nb)
            try:
                out.append(opt.refit_gram(sum(Gb[i] for i in pick) + G0,
                                          sum(bb[i] for i in pick) + b0, supp)[0])
            except (ValueError, np.linalg.LinAlgError):  # an infeasible resample is skipped
                continue
        return np.array(out) if out else np.empty((0, des.theta.shape[1]))


@final
@dataclass(frozen=True)
class ExponentProfile:
    """Profile likelihood of the dominant contact exponent over the joint fit.

    The ``delta^p`` term is swept over ``[low, high]`` (coarse step, then ``fine`` steps near
    the interval's ends and the minimum); at every ``p`` all coefficients are re-fitted and
    ``a0`` is profiled (grid plus bounded refinement). The 95 % interval is where
    ``n_rows log(RSS / RSS_min) <= 3.841`` with RSS and ``n_rows`` of the block-mean rows
    (:func:`block_mean_rss`); when it reaches ``low`` or ``high`` the data do
    not bound the exponent (``bounded`` False). ``cv_interval``: the exponents whose rolling
    cross-validation error (whole unseen set-points for three or more observations) is within
    one paired standard error of the best exponent's - a companion that does not rely on the
    rows' noise model (the profile likelihood does, and a law that cannot fit every orbit to
    noise makes it too narrow). With ``offsets`` the observations' gap
    offsets are re-fitted at every exponent (they trade with it).
    """

    low: float = 0.5
    high: float = 4.0
    step: float = 0.25
    fine: float = 0.05
    n_a0: int = 8
    offsets: bool = True

    def _rss(self, problem: JointProblem, lib: AFMLibrary, j: int, p: float,
             a0_hint: float) -> tuple[float, float, FloatArray]:
        lp = lib.replace(j, Indentation(float(p)))
        lo, hi = problem.a0_range
        grid = np.unique(np.concatenate([np.geomspace(lo, hi, self.n_a0), [a0_hint]]))
        best_a, best, _ = grid_then_bounded(lambda a: support_fit(problem, lp, a)[1], grid,
                                            maxiter=8)
        pr = problem
        if self.offsets and math.isfinite(best):
            # the orbits' offsets re-fitted at this exponent (they trade with it)
            pr2 = fit_offsets(problem, lp, best_a, support_fit(problem, lp, best_a)[0])
            if support_fit(pr2, lp, best_a)[1] < best:
                pr = pr2
        c, rss, des = support_fit(pr, lp, best_a)
        if not math.isfinite(rss):
            return math.inf, best_a, np.full(len(problem.blocks) - 1, np.inf)
        cv = cv_errors(des.optimizer(), des.theta, des.y, pr.blocks,
                       np.ones(des.theta.shape[1], bool), prior=pr.prior(des.theta.shape[1]))
        return block_mean_rss(pr, des, c)[0], best_a, cv

    def run(self, problem: JointProblem, lib: AFMLibrary, a0: float, p0: float
            ) -> dict[str, Any] | None:
        js = [j for j, t in enumerate(lib.terms) if isinstance(t, Indentation) and t.p == p0]
        if not js:
            return None
        j = js[0]
        c0, _, des0 = support_fit(problem, lib, a0)
        n_rows = block_mean_rss(problem, des0, c0)[1]
        pts: dict[float, tuple[float, float]] = {}

        def add(p: float) -> None:
            p = round(float(p), 6)
            if self.low - 1e-9 <= p <= self.high + 1e-9 and p not in pts:
                pts[p] = self._rss(problem, lib, j, p, a0)

        for p in np.arange(self.low, self.high + 1e-9, self.step):
            add(p)
        add(p0)

        def table() -> FloatArray:
            ks = sorted(pts)
            return np.array([(k, pts[k][0]) for k in ks])

        prof = table()
        lo_p, hi_p = profile_interval(prof, n_rows)
        p_best = float(prof[int(np.nanargmin(prof[:, 1])), 0])
        for centre in {lo_p, hi_p}:  # the interval's ends at the fine step
            if math.isfinite(centre):
                for p in np.arange(centre - self.step + self.fine, centre + self.step - 1e-9,
                                   self.fine):
                    add(p)
        prof = table()
        lo_p, hi_p = profile_interval(prof, n_rows)
        k = int(np.nanargmin(prof[:, 1]))
        p_best = float(prof[k, 0])
        bounded = bool(lo_p > self.low + 1e-9 and hi_p < self.high - 1e-9)
        # cross-validated companion: exponents whose rolling-CV error (unseen set-points when
        # the folds are observations) is within one paired standard error of the best one's
        ks = sorted(pts)
        cvs = np.array([pts[k][2] for k in ks])
        ok = np.all(np.isfinite(cvs), axis=1)
        cv_iv: tuple[float, float] = (math.nan, math.nan)
        if ok.any() and cvs.shape[1] >= 2:
            ib = int(np.argmin(np.where(ok, cvs.mean(axis=1), np.inf)))
            inside = []
            for i, kk in enumerate(ks):
                if not ok[i]:
                    continue
                d = cvs[i] - cvs[ib]
                if float(d.mean()) <= float(d.std(ddof=1)) / math.sqrt(d.size):
                    inside.append(kk)
            cv_iv = (float(min(inside)), float(max(inside)))
        return {"profile": prof, "interval": (lo_p, hi_p), "bounded": bounded,
                "best_exponent": p_best, "best_a0": pts[round(p_best, 6)][1],
                "n_rows": n_rows, "term_index": j, "cv_interval": cv_iv,
                "cv_bounded": bool(cv_iv[0] > self.low + 1e-9 and cv_iv[1] < self.high - 1e-9)}


# ---------------------------------------------------------------------------- pipeline
@final
@dataclass(frozen=True, eq=False)
class JointResult:
    """What :func:`fit_joint` found (immutable).

    Attributes
    ----------
    problem : JointProblem
        With the drive rotations and noise scale used in the final fit.
    library : AFMLibrary
        The chosen support's force terms (refined exponents).
    a0 : float
    coef : ndarray, shape (n_lin + n_terms,)
        Final coefficients ``[-D, -K, drive..., c_j...]``.
    samples : ndarray, shape (n_boot, n_lin + n_terms)
        Bootstrap coefficients.
    candidates : list of Candidate
    knee_index, ic_index : int
    ic_coef : ndarray
        Coefficients of the AICc choice (over the full library's columns).
    selection_library : AFMLibrary
        Library of the candidates' columns.
    selection_a0 : float
    a0_profile : ndarray, shape (n_a0, 2)
    exponent : dict or None
        :class:`ExponentProfile` output.
    refined : bool
    phase_info : dict
    output_error : OutputErrorResult or None
        The output-error stage's solution (its law is ``library``, ``a0``, ``coef``), None
        when the stage was off or its orbits were not found.
    """

    problem: JointProblem
    library: AFMLibrary
    a0: float
    coef: FloatArray
    samples: FloatArray
    candidates: list[Candidate]
    knee_index: int
    ic_index: int
    ic_coef: FloatArray
    selection_library: AFMLibrary
    selection_a0: float
    a0_profile: FloatArray
    exponent: dict[str, Any] | None
    refined: bool
    phase_info: dict[str, Any] = field(default_factory=dict)
    output_error: OutputErrorResult | None = None


def fit_joint(problem: JointProblem, library: AFMLibrary, *,
              drive: AbstractDrivePhase | None = None,
              onset: ContactOnsetProfile | None = None,
              selection: SupportSelection | None = None,
              refinement: Refinement | None = None,
              bagging: Bagging | None = None,
              exponent: ExponentProfile | None = None,
              offsets: OrbitOffsets | None = None,
              output_error: OutputErrorStage | None = DEFAULT_OUTPUT_ERROR,
              log: Any = None) -> JointResult:
    """Run the stages (module docstring) on ``problem`` with candidate terms ``library``.

    ``output_error`` is on by default (None: the equation-error law, bootstrap bands and
    :class:`ExponentProfile`); its exponent profile takes the range ``[low, high]`` of
    ``exponent`` when that is given.
    """
    def say(msg: str) -> None:
        if log is not None:
            log(msg)

    problem = (drive or RecordedPhase()).initial(problem)
    problem = NoiseScale().run(problem, library)
    say(f"a0 profile ({problem.n_obs} observations, {int(problem.rotated.sum())} with a "
        "recorded drive phase)")
    a0, a0_prof = (onset or ContactOnsetProfile()).run(problem, library)
    problem, phase_info = estimate_phases(problem, library, a0)
    if phase_info["method"] != "recorded":
        say(f"drive phases: {phase_info['method']}")
        a0, a0_prof = (onset or ContactOnsetProfile()).run(problem, library)
    say("model selection")
    sel = selection or SupportSelection()
    des, cands, ki, ii = sel.run(problem, library, a0)
    n_lin = problem.n_lin
    keep = cands[ki].coef[0][n_lin:] != 0
    if offsets is not None and keep.any():
        # the orbits' gap offsets for the chosen law, then select again with them
        say("orbit offsets; selecting again")
        problem = offsets.run(problem, des.library.subset(keep), des.a0)
        des, cands, ki, ii = sel.run(problem, library, des.a0)
        keep = cands[ki].coef[0][n_lin:] != 0
    lib_s = des.library.subset(keep)
    a0_s, refined = des.a0, False
    if offsets is not None and lib_s.n_terms:
        problem = offsets.run(problem, lib_s, a0_s)
    if refinement is not None and lib_s.n_terms:
        say("refining a0 and exponents")
        lib_s, a0_s, refined = refinement.run(problem, lib_s, a0_s)
        if offsets is not None and refined:
            problem = offsets.run(problem, lib_s, a0_s)
    coef, _, des_f = support_fit(problem, lib_s, a0_s)
    expo = None
    dominant = _dominant_exponent(problem, lib_s, a0_s, coef)
    oe = None
    if output_error is not None and lib_s.n_terms:
        say("output error: the law's own orbits against every observation")
        if exponent is not None and output_error.profile is not None:
            output_error = dataclasses.replace(output_error, profile=dataclasses.replace(
                output_error.profile, low=exponent.low, high=exponent.high))
        oe, expo = output_error.run(problem, lib_s, a0_s, coef, dominant,
                                    [*_contact_pair(library),
                                     *_later_terms(cands, ki, des.library, n_lin)],
                                    baseline=_contact_pair(library),
                                    linear=lambda lib, a: support_fit(problem, lib, a)[0])
        if oe is None:
            say("output error: an orbit of the equation-error law was not found; kept it")
    if oe is not None:
        lib_s, a0_s, coef = oe.library, oe.a0, oe.coef(problem)
        bag = bagging or Bagging(n_bootstrap=0)
        samples = covariance_samples(oe, problem, bag.n_bootstrap, bag.seed)
    else:
        samples = (bagging or Bagging(n_bootstrap=0)).run(problem, des_f)
        if exponent is not None and dominant is not None:
            say("exponent profile")
            expo = exponent.run(problem, lib_s, a0_s, dominant)
    return JointResult(problem=problem, library=lib_s, a0=a0_s, coef=coef, samples=samples,
                       candidates=cands, knee_index=ki, ic_index=ii,
                       ic_coef=np.asarray(cands[ii].coef[0]), selection_library=des.library,
                       selection_a0=des.a0, a0_profile=a0_prof, exponent=expo,
                       refined=refined, phase_info=phase_info, output_error=oe)


def _contact_pair(library: AFMLibrary) -> list[Any]:
    """The sphere's van der Waals term ``z^-2`` of ``library`` (held at ``a0`` in contact: the
    physics.md baseline's attraction, continuous at the onset) as a candidate; empty when
    the library has none."""
    return [t for t in library.terms if isinstance(t, InversePower) and t.n == 2.0][:1]


def _later_terms(cands: list[Candidate], knee: int, library: AFMLibrary, n_lin: int
                 ) -> list[Any]:
    """Force terms of the forward path's supports beyond the knee, in order of entry."""
    seen = cands[knee].coef[0][n_lin:] != 0
    out = []
    for c in cands[knee + 1:]:
        new = (c.coef[0][n_lin:] != 0) & ~seen
        for j in np.flatnonzero(new):
            out.append(library.terms[int(j)])
        seen |= new
    return out


def _dominant_exponent(problem: JointProblem, lib: AFMLibrary, a0: float, coef: FloatArray
                       ) -> float | None:
    """Exponent of the ``delta^p`` term with the largest RMS contribution on the orbits."""

    best, expo = 0.0, None
    cf = coef[problem.n_lin:]
    for j, t in enumerate(lib.terms):
        if not isinstance(t, Indentation) or cf[j] == 0:
            continue
        v = np.concatenate([t.evaluate(ti)
                            for ti in problem.orbit_inputs(a0, offsets=False)])
        contrib = abs(cf[j]) * float(np.sqrt(np.mean(v**2)))
        if contrib > best:
            best, expo = contrib, float(t.p)
    return expo
