"""One tip--sample law fitted jointly to several lock-in curves of the same lever and tip.

Curves recorded with one tip at several free amplitudes share the tip--sample force (in SI)
but not the surface position, the drive frequency or the drift of each recording. The joint
fit holds ONE law (the baseline's attraction and stiffness plus a hypothesis' terms, in the
length unit of the group, :attr:`GroupFitter.length_m_`) and per-curve nuisances: surface
position (``offset``), drive frequency / f0 (``omega``) and, for the drift hypothesis, the
drift rate (``drift``) and, with ``free_scale=True``, the free-amplitude scale
(``free_scale``: the drive's free amplitude / the amplitude measured at the ramp's far end, which
is the curve's length unit; a ramp that starts within reach of a long-range force does not
start free). Each curve is predicted with the shared law rescaled to its own free
amplitude (:func:`afmlearn.curves.transfer.rescale_law`, the SI force unchanged) by the
single-curve forward model (:class:`SlowFlowModel`); the residuals of all approaches are
weighted by each curve's noise and concatenated.

The finite-difference Jacobian is block-structured: a shared parameter moves every curve's
residual, a curve's nuisance only its own, so one Jacobian costs ``N (n_shared + n_nuisance)``
curve evaluations instead of ``N (n_shared + N n_nuisance)``.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Sequence
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from simulator.lockin import LockIn

from .curve import Curve
from .fit import (
    _SIGMA_FLOOR,
    DELTA_REF,
    OFFSET,
    OMEGA,
    RESCALES,
    CurveFitter,
    _dec,
    _enc,
    wrap_phase,
)
from .hypotheses import BASELINE, DRIFT, FREE_SCALE, Hypothesis, Parameter
from .law import CurveLaw
from .model import SlowFlowModel
from .transfer import rescale_law

__all__ = ["GroupFitter", "check_same_lever", "group_length", "offset_guess"]

log = logging.getLogger(__name__)

#: relative tolerance on k, f0 and Q for curves to count as one lever
LEVER_RTOL = 0.02
#: relative finite-difference step of the Jacobian (as the single fit's former
#: ``diff_step=1e-4``; 1e-6, which helped a single-curve fit, gave worse joint fits on the two
#: damped groups of the tests: chi2 1246 vs 1031, damping 25 % vs < 15 % off the truth)
DIFF_STEP = 1e-4


def check_same_lever(curves: Sequence[Curve], *, rtol: float = LEVER_RTOL) -> None:
    """Raise ValueError unless the curves' spring constant, f0 and Q agree within ``rtol``."""
    if len(curves) < 1:
        raise ValueError("curves: at least one curve is needed")
    for name in ("spring_constant_n_per_m", "resonance_frequency_hz", "quality_factor"):
        vals = np.array([getattr(c, name) for c in curves], dtype=float)
        if np.max(vals) > (1.0 + rtol) * np.min(vals):
            raise ValueError(f"curves: {name} differs between the curves of one group "
                             f"({np.min(vals):.6g} ... {np.max(vals):.6g}, allowed relative "
                             f"spread {rtol:g}): not one lever")


def group_length(curves: Sequence[Curve]) -> float:
    """Length unit of a group [m]: the geometric mean of the curves' free amplitudes."""
    return float(np.exp(np.mean([math.log(c.length_m) for c in curves])))


#: bounds of the per-curve free-amplitude scale (as the single fit's ``FREE_SCALE`` parameter)
FREE_SCALE_BOUNDS = (0.9, 3.0)

#: surface guess of a curve whose amplitude is never reduced below 90 %, below its closest
#: piezo position (/ free amplitude): out of the tip's reach within the +-0.6 bounds, so the
#: model's tip is not forced onto the surface (a fake dip that an extension would "explain")
FLAT_OFFSET = 1.5


def offset_guess(curve: Curve) -> float:
    """Surface position guess (/ free amplitude): the piezo position minus the amplitude where
    the approach's amplitude is reduced to 20--90 % (the single fit's scan centre); for a
    curve that never gets there, ``FLAT_OFFSET`` below its closest piezo position."""
    app = curve.segment == 0
    sel = app & (curve.amplitude > 0.2) & (curve.amplitude < 0.9)
    return (float(np.median(curve.z_piezo[sel] - curve.amplitude[sel])) if sel.any()
            else float(np.min(curve.z_piezo[app])) - FLAT_OFFSET)


def _closest(curve: Curve) -> float:
    """Smallest piezo position minus amplitude on the approach (/ free amplitude): the
    tip's closest recorded lower turning point relative to the piezo origin."""
    app = curve.segment == 0
    return float(np.min(curve.z_piezo[app] - curve.amplitude[app]))


class _Budget(Exception):
    """The evaluation budget is spent (internal)."""


@final
class GroupFitter:
    """Fit one law (baseline plus one hypothesis) jointly to the approaches of N curves.

    Parameters
    ----------
    hypothesis : Hypothesis or None
        Extra parameters on top of the baseline (``drift`` is a per-curve nuisance; every
        other parameter is shared).
    a0_m, tip_radius_m : float
        Contact onset and nominal tip radius [m] (fixed, as :class:`CurveFitter`).
    lockins : sequence of (LockIn or None), or None
        The recording filter of each curve (None: unfiltered).
    max_nfev : int
        Iterations of each least-squares refinement (function evaluations of
        ``least_squares``; a Jacobian costs ``N (n_shared + n_nuisance)`` curve evaluations).
    step : float
        Slow-flow time step (dimensionless).
    start : dict or None
        A previous joint fit's :attr:`values_` (``law`` fields in the group unit, ``curves``:
        one dict of nuisances per curve). None (and no ``extra_starts``): each curve's baseline
        is fitted alone (:class:`CurveFitter`) and every one of those laws is tried on the
        whole group.
    extra_starts : sequence of dict
        Further starts in the form of :attr:`values_` (e.g. single-curve fits of the same
        hypothesis), scored with the others.
    n_starts : int
        Refinements from the best starts.
    rescales : sequence of (float, float)
        Factors on ``vdw`` and ``stiffness`` tried around ``start`` (see :class:`CurveFitter`).
    max_evaluations : int or None
        Cap on curve evaluations (one forward model of one curve each). None: no cap.
    fixed_law : (CurveLaw, float) or None
        A law and its length unit [m] held fixed: only the nuisances are fitted (predicting
        curves not used to fit the law); their start is a scan of the surface positions.
    free_scale : bool
        Fit each curve's free-amplitude scale (``FREE_SCALE``, start 1, bounds
        ``FREE_SCALE_BOUNDS``) as a nuisance: the ramp's far end, where the curve's length unit
        and free phase are measured, need not be free (a long-range force already acting
        there). False: held at 1.
    rescan : bool
        With ``free_scale``: each curve's surface position scanned again under the best
        start's law (as for ``fixed_law``) before the refinement: under a long-range law the
        surface of a curve that never touches it can lie far from the amplitude's guess.

    Attributes
    ----------
    values_ : dict
        ``law``: shared fitted fields (group unit); ``curves``: per-curve ``offset``,
        ``omega`` (and ``drift``, ``free_scale``); ``length_m``: the group unit [m] (a start
        in another unit, e.g. of a subset of the curves, is rescaled to the same SI law).
    law_ : CurveLaw
        The shared law in the group unit (lengths / :attr:`length_m_`).
    length_m_ : float
        The group's length unit [m].
    chi2_ : float
        Weighted sum of squares over all fitted points.
    chi2_curves_ : list of float
        Its part per curve.
    n_fit_ : int
        Residuals fitted.
    n_evaluations_ : int
        Curve evaluations spent.
    curves_ : list of Curve
        The fitted curves.
    """

    def __init__(self, *, hypothesis: Hypothesis | None = None, a0_m: float = 0.3e-9,
                 tip_radius_m: float = 10e-9, lockins: Sequence[LockIn | None] | None = None,
                 max_nfev: int = 20, step: float = 4.0 * math.pi, start: dict | None = None,
                 extra_starts: Sequence[dict] = (), n_starts: int = 1,
                 rescales: tuple[tuple[float, float], ...] = RESCALES,
                 max_evaluations: int | None = None,
                 fixed_law: tuple[CurveLaw, float] | None = None,
                 free_scale: bool = False, rescan: bool = False) -> None:
        if hypothesis is not None and not isinstance(hypothesis, Hypothesis):
            raise ValueError(f"hypothesis must be a Hypothesis, got {type(hypothesis).__name__}")
        for name, v in (("a0_m", a0_m), ("tip_radius_m", tip_radius_m), ("step", step)):
            if not (math.isfinite(float(v)) and float(v) > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if int(max_nfev) < 1:
            raise ValueError(f"max_nfev must be >= 1, got {max_nfev!r}")
        if int(n_starts) < 1:
            raise ValueError(f"n_starts must be >= 1, got {n_starts!r}")
        if max_evaluations is not None and int(max_evaluations) < 1:
            raise ValueError(f"max_evaluations must be >= 1 or None, got {max_evaluations!r}")
        self.hypothesis = hypothesis
        self.a0_m = float(a0_m)
        self.tip_radius_m = float(tip_radius_m)
        self.lockins = lockins
        self.max_nfev = int(max_nfev)
        self.step = float(step)
        self.start = start
        self.extra_starts = tuple(extra_starts)
        self.n_starts = int(n_starts)
        self.rescales = tuple((float(a), float(b)) for a, b in rescales)
        self.max_evaluations = None if max_evaluations is None else int(max_evaluations)
        if fixed_law is not None and not (isinstance(fixed_law[0], CurveLaw)
                                          and float(fixed_law[1]) > 0.0):
            raise ValueError("fixed_law must be (CurveLaw, its length unit [m] > 0)")
        self.fixed_law = fixed_law
        self.free_scale = bool(free_scale)
        self.rescan = bool(rescan)

    # ------------------------------------------------------------------ public API
    def fit(self, curves: Sequence[Curve]) -> GroupFitter:
        """Fit on the approaches (``segment == 0``) of ``curves`` (one lever, one tip)."""
        curves = list(curves)
        check_same_lever(curves)
        n = len(curves)
        lockins = list(self.lockins) if self.lockins is not None else [None] * n
        if len(lockins) != n:
            raise ValueError(f"lockins must hold one entry per curve ({n}), got {len(lockins)}")
        self._curves, self._lockins = curves, lockins
        self.curves_ = curves
        self._masks = [c.segment == 0 for c in curves]
        self._sigma = [tuple(max(s, f) for s, f in zip(c.noise(), _SIGMA_FLOOR, strict=True))
                       for c in curves]
        self.length_m_ = group_length(curves)
        # lengths given in metres (the far-field decay) in the group's unit
        hyp = () if self.hypothesis is None else self.hypothesis.in_units(
            self.length_m_).parameters
        if self.fixed_law is None:
            self._base = CurveLaw(a0=self.a0_m / self.length_m_,
                                  radius=self.tip_radius_m / self.length_m_)
            # the free-amplitude scale is a per-curve nuisance, held at 1 in joint fits
            self._shared: list[Parameter] = list(BASELINE.parameters) + [
                p for p in hyp if p.field not in (DRIFT, FREE_SCALE)]
        else:
            law, length = self.fixed_law
            self._base = rescale_law(law, float(length) / self.length_m_)
            self._shared = []
        self._drift = next((p for p in hyp if p.field == DRIFT), None)
        self._n_nuis = 2 + (self._drift is not None) + self.free_scale
        self._w0 = [SlowFlowModel.for_curve(c).omega for c in curves]
        self._g0 = [offset_guess(c) for c in curves]
        lo, hi = [], []
        for i in range(n):
            low = self._g0[i] - 0.6
            if self.free_scale:
                # a long-range force reduces the amplitude far from the surface: the surface
                # may lie below the guess by as much as the tip stays above it at its closest
                # (session 9: an 8 nm curve under a charged tip, its surface 0.77 free
                # amplitudes below the guess, the tip 0.4 above the surface at the end)
                low = min(low, _closest(curves[i]) - 0.6)
            lo += [low, self._w0[i] - 0.005]
            hi += [self._g0[i] + 0.6, self._w0[i] + 0.005]
            if self._drift is not None:
                lo.append(self._drift.low)
                hi.append(self._drift.high)
            if self.free_scale:
                lo.append(FREE_SCALE_BOUNDS[0])
                hi.append(FREE_SCALE_BOUNDS[1])
        lo += [_enc(p, p.low) for p in self._shared]
        hi += [_enc(p, p.high) for p in self._shared]
        self._lo, self._hi = np.array(lo), np.array(hi)
        self.n_evaluations_ = 0
        self._unlimited = False
        self._cache: tuple[bytes, list[NDArray[np.float64]]] | None = None
        self._best: tuple[float, NDArray[np.float64]] | None = None
        starts = self._starts()
        for x0 in starts:
            self._refine(x0)
        self._set(self._best[1] if self._best is not None else starts[0])
        return self

    def predict(self, i: int, curve: Curve | None = None
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Amplitude (/ free amplitude) and lag [rad] of the whole curve ``i``, shape (m,)."""
        c = self._curves[i] if curve is None else curve
        return _predict(self.law_for(i), self.values_["curves"][i], c, self._lockins[i],
                        self.step)

    def law_for(self, i: int) -> CurveLaw:
        """The shared law in curve ``i``'s unit (its free amplitude)."""
        return rescale_law(self.law_, self.length_m_ / self._curves[i].length_m)

    # ------------------------------------------------------------------ internals
    def _remaining(self) -> int | None:
        if self.max_evaluations is None or self._unlimited:
            return None
        return self.max_evaluations - self.n_evaluations_

    def _encode(self, values: dict) -> NDArray[np.float64]:
        x = []
        for i, cv in enumerate(values["curves"]):
            x += [cv.get(OFFSET, self._g0[i]), cv.get(OMEGA, self._w0[i])]
            if self._drift is not None:
                x.append(cv.get(DRIFT, self._drift.init))
            if self.free_scale:
                x.append(cv.get(FREE_SCALE, 1.0))
        law = values["law"]
        unit = values.get("length_m")
        if law and unit is not None and abs(unit / self.length_m_ - 1.0) > 1e-12:
            # a start in another length unit (another set of curves): the same SI law here
            own = CurveLaw(a0=self.a0_m / unit, radius=self.tip_radius_m / unit).replace(**law)
            own = rescale_law(own, unit / self.length_m_)
            law = {k: getattr(own, k) for k in law}
        x += [_enc(p, law.get(p.field, self._default(p))) for p in self._shared]
        return np.clip(np.array(x, dtype=float), self._lo + 1e-9, self._hi - 1e-9)

    def _default(self, p: Parameter) -> float:
        """A parameter missing from a start: the baseline law's own value where that is a
        valid one (the exponent 1.5), else the parameter's ``init``."""
        v = getattr(self._base, p.field, None)
        if v is not None and p.low <= v <= p.high and (v > 0.0 or not p.log):
            return float(v)
        return p.init

    def _decode(self, x: NDArray[np.float64]) -> dict:
        k = self._n_nuis
        curves = []
        for i in range(len(self._curves)):
            cv = {OFFSET: float(x[k * i]), OMEGA: float(x[k * i + 1])}
            if self._drift is not None:
                cv[DRIFT] = float(x[k * i + 2])
            if self.free_scale:
                cv[FREE_SCALE] = float(x[k * i + k - 1])
            curves.append(cv)
        law = {p.field: _dec(p, xi) for p, xi in zip(self._shared, x[k * len(self._curves):],
                                                      strict=True)}
        return {"law": law, "curves": curves}

    def _residual_one(self, i: int, values: dict) -> NDArray[np.float64]:
        left = self._remaining()
        if left is not None and left <= 0:
            raise _Budget
        self.n_evaluations_ += 1
        c, m, s = self._curves[i], self._masks[i], self._sigma[i]
        law = rescale_law(self._base.replace(**values["law"]), self.length_m_ / c.length_m)
        a, p = _predict(law, values["curves"][i], c, self._lockins[i], self.step)
        out = np.concatenate([(a - c.amplitude)[m] / s[0], wrap_phase(p - c.phase)[m] / s[1]])
        return np.where(np.isfinite(out), out, 1e6)

    def _parts(self, x: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        v = self._decode(x)
        parts = [self._residual_one(i, v) for i in range(len(self._curves))]
        self._cache = (key, parts)
        cost = float(sum(p @ p for p in parts))
        if self._best is None or cost < self._best[0]:
            self._best = (cost, x.copy())
        return parts

    def _residual(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate(self._parts(x))

    def _jacobian(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        parts = self._parts(x)
        sizes = [p.size for p in parts]
        edges = np.concatenate([[0], np.cumsum(sizes)])
        r0 = np.concatenate(parts)
        jac = np.zeros((r0.size, x.size))
        k = self._n_nuis
        n = len(self._curves)
        for j in range(x.size):
            h = DIFF_STEP * max(1.0, abs(x[j]))
            y = x.copy()
            y[j] = x[j] + h if x[j] + h <= self._hi[j] else x[j] - h
            h = y[j] - x[j]
            v = self._decode(y)
            if j < k * n:  # a nuisance of curve i: only its own residual moves
                i = j // k
                jac[edges[i]:edges[i + 1], j] = (self._residual_one(i, v) - parts[i]) / h
            else:
                r = np.concatenate([self._residual_one(i, v) for i in range(n)])
                jac[:, j] = (r - r0) / h
        return jac

    def _cost(self, x: NDArray[np.float64]) -> float:
        try:
            r = self._residual(x)
        except _Budget:
            return math.inf
        return float(r @ r)

    def _refine(self, x0: NDArray[np.float64]) -> None:
        """Bounded least squares from ``x0`` within the budget (the best point seen is kept
        in ``_best``)."""
        n = len(self._curves)
        per_iter = n * (1 + len(self._shared) + self._n_nuis)
        nfev = self.max_nfev
        left = self._remaining()
        if left is not None:
            nfev = min(nfev, (left - n) // per_iter)
            if nfev < 1:
                return
        try:
            optimize.least_squares(self._residual, x0, jac=self._jacobian,
                                   bounds=(self._lo, self._hi), method="trf",
                                   x_scale="jac", max_nfev=nfev)
        except _Budget:
            pass

    def _starts(self) -> list[NDArray[np.float64]]:
        """Start vectors, best first (scored by the joint cost)."""
        cands: list[NDArray[np.float64]] = []
        if self.fixed_law is not None:
            return self._offset_scan()
        if self.start is not None:
            cands += self._rescaled(self._encode(self.start))
        elif not self.extra_starts:
            cands += self._single_starts()
        left = self._remaining()
        n = len(self._curves)
        if left is not None and len(cands) > 1 and len(cands) * n > left // 3:
            # at most a third of the budget on scoring starts: every k-th (the first, the
            # start itself, always)
            k = math.ceil(len(cands) * n / max(1, left // 3))
            cands = cands[::k]
        cands += [self._encode(s) for s in self.extra_starts]
        if self.free_scale:
            cands = [self._far_start(c) for c in cands]
        if len(cands) > 1:
            costs = [(self._cost(c), k) for k, c in enumerate(cands)]
            costs.sort()
            log.info("group fit %s: %d starts scored, best cost %.4g",
                     self.hypothesis.cause if self.hypothesis else "baseline", len(cands),
                     costs[0][0])
            cands = [cands[k] for _, k in costs[: self.n_starts]]
        if self.free_scale and self.rescan:
            cands = [self._offset_scan(c)[0] for c in cands]
        return cands

    def _offset_scan(self, x0: NDArray[np.float64] | None = None
                     ) -> list[NDArray[np.float64]]:
        """Fixed law: each curve's surface position scanned around its guess, coarse
        (-0.3 ... 0.3 free amplitudes, step 0.02; with free scales from the lower bound) then
        fine (step 0.004) around the best: whether the tip reaches the contact turns on a
        fraction of a nanometre. ``x0``: a start whose law is scanned under (default: the
        fixed law, every nuisance at its guess)."""
        n = len(self._curves)
        k = self._n_nuis
        x = (self._encode({"law": {}, "curves": [{} for _ in range(n)]}) if x0 is None
             else x0.copy())
        # with free scales, down to the lowest bound of any curve's surface (a long-range
        # force reduces the amplitude far from the surface), same step
        reach = min(-0.3, min(self._lo[k * i] - self._g0[i] for i in range(n))
                    if self.free_scale else -0.3)
        # a rescan of a joint start (every hypothesis fit with a long-range law): coarser
        step, fine = (0.02, 0.02) if x0 is None else (0.05, 0.04)
        coarse = np.arange(0.3, reach - 1e-9, -step)
        # nearest to the guess first: a scan cut short by the budget keeps the near positions
        coarse = coarse[np.argsort(np.abs(coarse), kind="stable")]
        for grid in (coarse, np.linspace(-fine, fine, 11)):
            best = [(math.inf, float(x[k * i])) for i in range(n)]
            base = x.copy()
            for d in grid:
                y = base.copy()
                y[0:k * n:k] = base[0:k * n:k] + d
                v = self._decode(y)
                for i in range(n):
                    try:
                        r = self._residual_one(i, v)
                    except _Budget:
                        break
                    best[i] = min(best[i], (float(r @ r), float(y[k * i])))
            for i in range(n):
                x[k * i] = best[i][1]
        x = np.clip(x, self._lo + 1e-9, self._hi - 1e-9)
        return [self._far_start(x) if self.free_scale else x]

    def _far_start(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x`` with each curve's drive frequency and free-amplitude scale set so that the
        model's far end (the curve's free reference part, :meth:`Curve.far`) has the recorded
        lag and amplitude under ``x``'s law: from the model's far lag ``phi`` the linear lever's
        detuning ``D = (W/Q) / tan(phi)`` (the force gradient included), the drive frequency
        ``W'`` with ``atan2(W'/Q, D - (W'**2 - W**2))`` the recorded lag, and the scale by the
        amplitude ratio, corrected for the move of ``W``. One prediction of the far part per
        curve (15 % of the approach and the settling: all curves' together are counted as one
        curve evaluation)."""
        v = self._decode(x)
        law = self._base.replace(**v["law"])
        k = self._n_nuis
        y = x.copy()
        left = self._remaining()
        if left is not None and left <= 0:
            return x
        self.n_evaluations_ += 1
        for i, c in enumerate(self._curves):
            far = c.far()
            part = c.subset(np.arange(c.n) <= far[-1])
            a, p = _predict(rescale_law(law, self.length_m_ / c.length_m), v["curves"][i], part,
                            self._lockins[i], self.step)
            a_m, p_m = float(np.median(a[far])), float(np.median(p[far]))
            a_r, p_r = float(np.median(c.amplitude[far])), c.free_phase
            w, s = v["curves"][i][OMEGA], v["curves"][i][FREE_SCALE]
            q = c.quality_factor
            if not (0.0 < p_m < math.pi and 0.0 < p_r < math.pi and a_m > 0.0):
                continue
            d = (w / q) / math.tan(p_m)
            # W'^2 from atan2(W'/Q, D - (W'^2 - W^2)) = p_r with W'/Q ~ W/Q
            w2 = w * w + d - (w / q) / math.tan(p_r)
            if w2 <= 0.0:
                continue
            w_new = float(np.clip(math.sqrt(w2), self._lo[k * i + 1] + 1e-9,
                                  self._hi[k * i + 1] - 1e-9))
            d_new = d - (w_new * w_new - w * w)
            # the model amplitude at W' (same scale) relative to W's, linear lever
            ratio = (math.hypot(1.0 - w_new * w_new, w_new / q)
                     / math.hypot(1.0 - w * w, w / q)
                     * math.hypot(d, w / q) / math.hypot(d_new, w_new / q))
            y[k * i + 1] = w_new
            y[k * i + k - 1] = s * a_r / (a_m * ratio)
        return np.clip(y, self._lo + 1e-9, self._hi - 1e-9)

    def _single_starts(self) -> list[NDArray[np.float64]]:
        """Each curve's baseline fitted alone; each of those laws (rescaled to the group
        unit) with every curve's own nuisances."""
        n = len(self._curves)
        left = self._remaining()
        share = None if left is None else max(2, left // (2 * n))
        fits = []
        for c, lk in zip(self._curves, self._lockins, strict=True):
            f = CurveFitter(a0_m=self.a0_m, tip_radius_m=self.tip_radius_m, lockin=lk,
                            step=self.step, max_evaluations=share).fit(c)
            self.n_evaluations_ += f.n_evaluations_
            fits.append(f)
        nuis = [{OFFSET: f.values_[OFFSET], OMEGA: f.values_[OMEGA]} for f in fits]
        out = []
        for f, c in zip(fits, self._curves, strict=True):
            law = rescale_law(f.law_, c.length_m / self.length_m_)
            out.append(self._encode({"law": {p.field: getattr(law, p.field)
                                             for p in self._shared}, "curves": nuis}))
        return out

    def _rescaled(self, x: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        """The start with the hypothesis' shared parameters at each of their starting values
        (the start's, ``init``, ``alternatives``), each with ``vdw`` and ``stiffness`` rescaled
        (a changed exponent keeps the contact force at ``DELTA_REF``)."""
        k0 = self._n_nuis * len(self._curves)
        idx = {p.field: k0 + j for j, p in enumerate(self._shared)}
        extra = [p for p in self._shared if p.field not in ("vdw", "stiffness")]
        law = (self.start or {}).get("law", {})
        choices = []
        for p in extra:
            vals = [float(x[idx[p.field]])]
            for a in (p.init, *p.alternatives):
                if all(abs(_enc(p, a) - v) > 1e-12 for v in vals):
                    vals.append(_enc(p, a))
            choices.append(vals)
        e0 = law.get("exponent", self._base.exponent)
        out = []
        for combo in itertools.product(*choices):
            y = x.copy()
            for p, v in zip(extra, combo, strict=True):
                y[idx[p.field]] = v
            de = e0 - y[idx["exponent"]] if "exponent" in idx else 0.0
            for fv, fs in self.rescales or ((1.0, 1.0),):
                z = y.copy()
                z[idx["vdw"]] += math.log10(fv)
                z[idx["stiffness"]] += math.log10(fs) + de * math.log10(DELTA_REF)
                out.append(np.clip(z, self._lo + 1e-9, self._hi - 1e-9))
        if not any(np.allclose(z, x) for z in out):
            out.insert(0, x)
        return out

    def _set(self, x: NDArray[np.float64]) -> None:
        self.x_ = x
        self.values_ = {**self._decode(x), "length_m": self.length_m_}
        self.law_ = self._base.replace(**self.values_["law"])
        self._unlimited = True  # the final residual is always computed
        parts = self._parts(x)
        self.chi2_curves_ = [float(p @ p) for p in parts]
        self.chi2_ = float(sum(self.chi2_curves_))
        self.n_fit_ = int(sum(p.size for p in parts))


def _predict(law: CurveLaw, nuisances: dict, curve: Curve, lockin: LockIn | None,
             step: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Amplitude and lag of ``curve`` under ``law`` (its unit) and its nuisances (the drive
    gives the free amplitude ``free_scale``, 1 when not fitted)."""
    w = nuisances[OMEGA]
    q = curve.quality_factor
    model = SlowFlowModel(quality_factor=q, omega=w,
                          drive=nuisances.get(FREE_SCALE, 1.0) * math.hypot(1.0 - w * w, w / q),
                          lockin=lockin, step=step)
    gap = (curve.z_piezo - nuisances[OFFSET]
           + nuisances.get(DRIFT, 0.0) * (curve.tau - curve.tau[0]))
    return model.predict(law, curve.tau, gap)
