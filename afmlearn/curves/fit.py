"""Fit one tip--sample law to the approach branch of a lock-in curve (weighted least squares)."""

from __future__ import annotations

import itertools
import logging
import math
from abc import ABC, abstractmethod
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from simulator.lockin import LockIn

from .curve import Curve
from .hypotheses import BASELINE, DRIFT, FREE_SCALE, Hypothesis, Parameter
from .law import CurveLaw
from .model import SlowFlowModel

__all__ = ["CurveFitter", "DataFarStart", "FAR_BASINS", "FarStart", "LeverFarStart", "OFFSET",
           "SlopeFarStart", "wrap_phase"]

log = logging.getLogger(__name__)

#: name of the surface position (piezo coordinate where the rest gap is zero)
OFFSET = "offset"
#: name of the drive frequency / f0 (a nuisance: the free phase is biased by long-range forces)
OMEGA = "omega"
#: floors of the residual weights (amplitude / free amplitude, phase [rad])
_SIGMA_FLOOR = (1e-3, math.radians(0.05))
#: factors on the attraction ``vdw`` and the contact ``stiffness`` tried around a solution: the
#: cost is rough near the bistable jump and a new term (an electrostatic tail, another contact
#: exponent) trades against the baseline's attraction and stiffness
RESCALES = ((1.0, 1.0), (0.3, 1.0), (0.03, 1.0), (1.0, 3.0), (1.0, 0.3), (0.3, 3.0))
#: fine scans of the surface position around the coarse scan's best (/ free amplitude): whether
#: the model's tip reaches the contact turns on a fraction of a nanometre
FINE_OFFSETS = tuple(np.linspace(-0.06, 0.06, 25))
#: factors on vdw and stiffness of that fine grid
FINE_SCALES = ((0.25, 0.5, 1.0, 2.0, 4.0), (0.1, 0.3, 1.0, 3.0, 10.0))
#: indentation (/ free amplitude) at which the contact force is held when the exponent changes
DELTA_REF = 0.02
#: half-width and step of the surface positions profiled from one evaluation (/ free amplitude):
#: on a linear approach ramp a shift of the surface is a shift in time of the whole prediction
PROFILE_WINDOW = 0.06
PROFILE_STEP = 0.001
#: relative finite-difference step of the least-squares Jacobian: the residuals bend within
#: 1e-4 of the drive frequency and the surface position (measured: with 1e-4 a no-effect
#: baseline stops at 3.7x the truth's chi2 by xtol after 10 evaluations, with 1e-6 at 1.2x)
DIFF_STEP = 1e-6
#: how far (free amplitudes) the surface may lie beyond the closest piezo position when the
#: amplitude never falls below 0.9 of free
OUT_OF_REACH = 3.0
#: half-width profiled around the baseline's first guess of the surface position
COARSE_WINDOW = 0.15
#: the baseline's coarse (vdw, stiffness) grid and the fine factors around its best when the
#: surface position is profiled. Half decades of stiffness too: the valley runs diagonally
#: (more attraction, softer contact) and is ~0.3 decades wide in stiffness; with whole decades
#: the coarse best sat beside it (entry-point test curve: coarse best chi2 4347, refined to
#: 1054-4347 by 1e-10 changes of the data; test_fit's far-field damping case: baseline stuck
#: at 2468 with stiffness 113 against the truth-started 188 with 15)
PROFILED_COARSE = (tuple(10.0 ** np.arange(-7.0, -2.9, 0.5)),
                   tuple(10.0 ** np.arange(0.0, 3.1, 0.5)))
PROFILED_FINE_SCALES = (tuple(2.0 ** (np.arange(-8, 9) / 8.0)),
                        (0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0))
#: starts refined beyond ``n_starts`` (each from a distinct point of the scan, see
#: ``DISTINCT``), the best refined fit is kept: one refinement lands in one of several close
#: valleys depending on the last digits of the data (measured: held-out NRMSE 0.030 / 0.054 on
#: the entry-point test's curve simulated twice 1e-12 apart)
N_EXTRA_STARTS = 2
#: smallest difference (offset / free amplitude, drive frequency, then every other
#: coordinate: log10 of the law's scales) for two scan points to count as distinct starts
DISTINCT = (0.005, 1e-4, 0.1)
#: the short runs of the starts get this fraction of ``max_nfev`` (the best one continues)
RACE_FRACTION = 4
#: relative cost difference below which two refined fits tie (the better-scored start wins)
TIE_TOLERANCE = 1e-6
#: restarts of the least squares after a stop on its step tolerance, and the relative gain
#: a restart must bring for the next
N_POLISH = 4
POLISH_GAIN = 1e-3
#: largest rms deviation of the approach's piezo positions from a line (/ free amplitude) for the
#: profile to be used (else every start is scored at its own surface position)
RAMP_TOLERANCE = 0.005
#: adaptive slow-flow steps one evaluation may take before it counts as more than one against
#: ``max_evaluations``: a deep, stiff repulsive contact is stiff for the explicit steps (measured
#: on Asylum AZ_0081, 128 nm: 2,865 steps, 90 % of them in the last tenth of the approach,
#: 35 ms, against 400-1,100 steps and 5 ms on most curves; 5,000+ steps at a stiffness of 8e4),
#: so an evaluation budget alone did not bound the time per curve (43-52 s on 3 of 48 curves)
WORK_STEPS = 1000
#: rest gap (/ free amplitude) beyond which the approach shows no conservative force, only a
#: far loss: the points read for the far damping term's start (``_far_law_from_data``)
FAR_GAP = 2.0
#: fraction of the far decay's upper bound beyond which the data-read law counts as no resolved
#: decay (a loss linear over the ramp): then the linear-slope basin is started too
SLOPE_FRACTION = 0.5
#: far coefficient of the linear-slope start when the data show no slope (/ the lever's own
#: damping 1/Q): the level of the forced fits on the flat Asylum curves (0.010-0.017x, s8)
SLOPE_LEVEL = 0.01


class FarStart(ABC):
    """One basin of the far damping term: its starts ``(coefficient, decay length)`` (encoded,
    as the fit's coordinates). Each basin is refined on its own and the fit keeps the lowest
    chi2 (``CurveFitter``): one curve's far loss fits in two or three basins (Asylum, session
    8: ~550 nm at free-amplitude scale 1.00 and 2-5 um at ~1.1; a short race between them
    kept the worse one on 25/48 On_Surface and 35/38 Off declining curves)."""

    @abstractmethod
    def starts(self, fitter: CurveFitter, x: NDArray[np.float64],
               params: list[Parameter]) -> list[tuple[float, float]]:
        """Starts of this basin around ``x`` (may be empty)."""


@final
class LeverFarStart(FarStart):
    """``x``'s far term and each of the coefficient's ``alternatives`` at ``x``'s decay
    (``FAR_DECAY_M``: 3e-4 k/omega0 over 500 nm, session 6's start)."""

    def starts(self, fitter: CurveFitter, x: NDArray[np.float64],
               params: list[Parameter]) -> list[tuple[float, float]]:
        pc, c0, l0 = _far_coordinates(x, params)
        return [(c0, l0)] + [(_enc(pc, a), l0) for a in pc.alternatives if _enc(pc, a) != c0]


@final
class DataFarStart(FarStart):
    """The far law read off the approach beyond ``FAR_GAP`` (``_far_law_from_data``, session
    7's start; needed where the loss decays over more than the ramp: a 2-3 um decay on a
    1.2 um ramp stalled from 500 nm). None when the far points show no loss."""

    def starts(self, fitter: CurveFitter, x: NDArray[np.float64],
               params: list[Parameter]) -> list[tuple[float, float]]:
        far = fitter._far_law_from_data(x)
        if far is None:
            return []
        pc, pl = _far_parameters(params)
        return [(_enc(pc, far[0]), _enc(pl, far[1]))]


@final
class SlopeFarStart(FarStart):
    """The linear-slope basin, only where the data resolve no decay (the data-read law is None
    or decays over more than ``SLOPE_FRACTION`` of the upper bound): the decay at its upper
    bound, the coefficient read off the far points at that decay (at least ``SLOPE_LEVEL``
    of the lever's damping). On the flat Asylum curves this basin lowered chi2 by 77-449 on
    13/37 but no start reached it (session 8); a free-amplitude drift over the ramp makes the
    same slope (docs/real_data.md, session 9)."""

    def starts(self, fitter: CurveFitter, x: NDArray[np.float64],
               params: list[Parameter]) -> list[tuple[float, float]]:
        pc, pl = _far_parameters(params)
        far = fitter._far_law_from_data(x)
        if far is not None and far[1] < SLOPE_FRACTION * pl.high:
            return []
        hi = _enc(pl, pl.high) - 1e-6 * (abs(_enc(pl, pl.high)) + 1.0)
        coef = fitter._far_law_from_data(x, decay=_dec(pl, hi))
        q = fitter.model_.quality_factor
        level = max(coef[0] if coef is not None else 0.0, SLOPE_LEVEL / q)
        return [(_enc(pc, min(max(level, pc.low), pc.high)), hi)]


#: the far term's basins, each refined on its own (the fit keeps the lowest chi2); the data's
#: basins only when the free-amplitude scale starts from the data (a first extension fit)
FAR_BASINS: tuple[FarStart, ...] = (LeverFarStart(), DataFarStart(), SlopeFarStart())


@final
class CurveFitter:
    """Fit the baseline law plus one hypothesis' parameters to a curve's approach branch.

    Parameters
    ----------
    hypothesis : Hypothesis
        Extra parameters on top of the baseline (``None``: the baseline alone).
    a0_m : float
        Contact onset [m] (held fixed: with the surface position it is not identifiable).
    tip_radius_m : float
        Nominal tip radius [m] (radius of the electrostatic term).
    lockin : LockIn or None
        The recording lock-in's filter (None: unfiltered).
    max_nfev : int
        Function evaluations of the least-squares refinement.
    start : dict or None
        Starting values by field name (``offset``, law fields, ``drift``): a previous fit.
    step : float
        Time step of the slow flow (dimensionless; default two drive periods).
    n_starts : int
        Least-squares runs from the best points of the start scan (the bistable jump makes
        the cost rough: more starts, fewer local minima); the best fit is kept.
    rescales : sequence of (float, float)
        Factors on ``vdw`` and ``stiffness`` tried around the starting point (with a ``start``:
        combined with every starting value of the hypothesis' parameters; without: around the
        scan's solution, refined once more if one of them is better). ``()``: none.
    max_evaluations : int or None
        Cap on the model evaluations of this fit (start scan and refinement; a refinement
        iteration costs one evaluation per fitted parameter plus one). An evaluation whose slow
        flow takes ``s`` > ``WORK_STEPS`` adaptive steps counts as ``s / WORK_STEPS``
        evaluations (the cap bounds the work, i.e. the CPU time, also on stiff deep contacts).
        None: no cap.
    far_basins : sequence of FarStart
        Basins of the far damping term (a hypothesis with one), each refined on its own
        within an equal share of what the start scan left of the budget; the lowest chi2 is
        kept (``FAR_BASINS``; one basin: the best-scored start of all, session 8).

    Attributes
    ----------
    law_ : CurveLaw
        Fitted law (dimensionless, lengths / free amplitude).
    offset_ : float
        Surface position in piezo coordinates (/ free amplitude).
    drift_ : float
        Drift of the rest gap per unit time (0 unless fitted).
    values_ : dict
        Every fitted parameter by name.
    chi2_ : float
        Weighted sum of squares on the fitted points.
    n_fit_ : int
        Number of residuals fitted.
    model_ : SlowFlowModel
    sigma_ : tuple of float
        Amplitude and phase noise used as weights.
    n_evaluations_ : float
        Model evaluations spent (counted by their work, see ``max_evaluations``).
    basins_ : list of (float, dict)
        Chi2 and fitted values of each far basin refined (best first; one entry without a
        far term).
    """

    def __init__(self, *, hypothesis: Hypothesis | None = None, a0_m: float = 0.3e-9,
                 tip_radius_m: float = 10e-9, lockin: LockIn | None = None,
                 max_nfev: int = 60, start: dict | None = None,
                 step: float = 4.0 * math.pi, n_starts: int = 1,
                 rescales: tuple[tuple[float, float], ...] = RESCALES,
                 max_evaluations: int | None = None,
                 far_basins: tuple[FarStart, ...] = FAR_BASINS) -> None:
        if hypothesis is not None and not isinstance(hypothesis, Hypothesis):
            raise ValueError(f"hypothesis must be a Hypothesis, got {type(hypothesis).__name__}")
        for name, v in (("a0_m", a0_m), ("tip_radius_m", tip_radius_m)):
            if not (math.isfinite(float(v)) and float(v) > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if int(max_nfev) < 1:
            raise ValueError(f"max_nfev must be >= 1, got {max_nfev!r}")
        self.hypothesis = hypothesis
        self.a0_m = float(a0_m)
        self.tip_radius_m = float(tip_radius_m)
        self.lockin = lockin
        self.max_nfev = int(max_nfev)
        self.start = start
        if not (math.isfinite(float(step)) and float(step) > 0.0):
            raise ValueError(f"step must be a finite number > 0, got {step!r}")
        self.step = float(step)
        if int(n_starts) < 1:
            raise ValueError(f"n_starts must be >= 1, got {n_starts!r}")
        self.n_starts = int(n_starts)
        for r in rescales:
            if len(r) != 2 or not all(math.isfinite(f) and f > 0 for f in r):
                raise ValueError(f"rescales must be pairs of finite factors > 0, got {r!r}")
        self.rescales = tuple((float(a), float(b)) for a, b in rescales)
        if max_evaluations is not None and int(max_evaluations) < 1:
            raise ValueError(f"max_evaluations must be >= 1 or None, got {max_evaluations!r}")
        self.max_evaluations = None if max_evaluations is None else int(max_evaluations)
        far_basins = tuple(far_basins)
        if not far_basins or not all(isinstance(b, FarStart) for b in far_basins):
            raise ValueError(f"far_basins must be a non-empty sequence of FarStart, "
                             f"got {far_basins!r}")
        self.far_basins = far_basins

    # ------------------------------------------------------------------ public API
    def fit(self, curve: Curve, *, mask: NDArray[np.bool_] | None = None) -> CurveFitter:
        """Fit on the points ``mask`` (default: the approach, ``segment == 0``)."""
        mask = curve.segment == 0 if mask is None else np.asarray(mask, dtype=bool)
        self.model_ = SlowFlowModel.for_curve(curve, lockin=self.lockin, step=self.step)
        self.sigma_ = tuple(max(s, f) for s, f in zip(curve.noise(), _SIGMA_FLOOR, strict=True))
        self._curve, self._mask = curve, mask
        # the model is causal: nothing after the last fitted point is integrated
        self._end = int(np.flatnonzero(mask)[-1]) + 1 if mask.any() else curve.n
        self._ramp = _linear_ramp(curve, mask)
        self._base = CurveLaw(a0=self.a0_m / curve.length_m,
                              radius=self.tip_radius_m / curve.length_m)
        params = list(BASELINE.parameters)
        if self.hypothesis is not None:
            # lengths given in metres (the far-field decay) in this curve's unit
            params += list(self.hypothesis.in_units(curve.length_m).parameters)
        self._params = params
        self.n_evaluations_ = 0
        self._unit = 1.0  # the work of the last evaluation (in evaluations)
        self._share: float | None = None
        basins = self._start(curve, params)
        starts = [x for b in basins for x in b]
        w0 = self.model_.omega
        lo = np.array([self._offset_bounds[0], w0 - 0.005] + [_enc(p, p.low) for p in params])
        hi = np.array([self._offset_bounds[1], w0 + 0.005] + [_enc(p, p.high) for p in params])
        self._lo, self._hi = lo, hi
        best, done = None, []
        basins = [b for b in basins if b]
        log.debug("%s: %d basins, %.0f of %s evaluations spent on the starts",
                  "baseline" if self.hypothesis is None else self.hypothesis.cause,
                  len(basins), self.n_evaluations_, self.max_evaluations)
        for i, b in enumerate(basins):
            if self.max_evaluations is not None:
                # an equal share of what is left for each basin not yet refined
                self._share = self.n_evaluations_ + (
                    self.max_evaluations - self.n_evaluations_) / (len(basins) - i)
            res = self._race(b)
            if res is not None:
                res = self._polish(res)
                done.append(res)
                if best is None or res.cost < best.cost * (1.0 - TIE_TOLERANCE):
                    best = res
        self._share = None
        self.basins_ = [(2.0 * r.cost, self._values(r.x))
                        for r in sorted(done, key=lambda r: r.cost)]
        x = best.x if best is not None else np.clip(starts[0], lo, hi)
        self._set(x)
        r = self._residual(x)
        self.chi2_ = float(r @ r)
        self.n_fit_ = int(r.size)
        return self

    def _remaining(self) -> float | None:
        if self.max_evaluations is None:
            return None
        # one evaluation (of the last one's work) is kept for the final residual; a basin's
        # refinement stops at its share (``_share``)
        limit = self.max_evaluations if self._share is None else self._share
        return limit - self._unit - self.n_evaluations_

    def _count(self, model: SlowFlowModel) -> None:
        """Count one evaluation of ``model`` by its work (``WORK_STEPS``)."""
        steps = model.n_steps_ if model.tolerance is not None else 0
        self._unit = max(1.0, steps / WORK_STEPS)
        self.n_evaluations_ += self._unit

    def _refine(self, x0: NDArray[np.float64], *, share: int = 1,
                max_nfev: int | None = None):
        """One bounded least-squares run from ``x0`` within ``1 / share`` of the evaluation
        budget left (None when nothing is left)."""
        x0 = np.clip(x0, self._lo + 1e-9, self._hi - 1e-9)
        nfev = self.max_nfev if max_nfev is None else max_nfev
        left = self._remaining()
        if left is not None:
            # an iteration costs one evaluation plus one per parameter (the Jacobian), each
            # counted by its work (that of the last evaluation)
            nfev = int(min(nfev, (left // max(1, share) - 1) // ((x0.size + 2) * self._unit)))
            if nfev < 1:
                return None
        return optimize.least_squares(self._residual, x0, bounds=(self._lo, self._hi),
                                      method="trf", x_scale="jac", diff_step=DIFF_STEP,
                                      max_nfev=nfev)

    def _race(self, starts: list[NDArray[np.float64]]):
        """Refine every start briefly (``max_nfev / RACE_FRACTION``), then the best of them to
        the end; one start: refined to the end. None when the budget is spent.

        Which of several close valleys one refinement reaches turns on the last digits of the
        data (the cost is rough near the bistable jump); the best of a few short runs from
        distinct starts does not. Among near-equal short runs (``TIE_TOLERANCE``) the
        better-scored start wins.
        """
        if len(starts) == 1:
            return self._refine(starts[0])
        best = None
        short = max(2, self.max_nfev // RACE_FRACTION)
        for i, x0 in enumerate(starts):
            # the budget left is shared by the starts not yet refined and the final run
            res = self._refine(x0, share=len(starts) - i + 1, max_nfev=short)
            if res is not None and (best is None or res.cost < best.cost * (1.0 - TIE_TOLERANCE)):
                best = res
        if best is None or best.status != 0:  # stopped before its cap: converged or stalled
            return best
        more = self._refine(best.x, max_nfev=self.max_nfev - short)
        return more if more is not None and more.cost < best.cost else best

    def _polish(self, res):
        """Restart the least squares from ``res`` while it stopped on its step tolerance and
        the restart gains more than ``POLISH_GAIN`` (relative): near the bistable jump the
        trust region collapses on a finite-difference Jacobian that misreads the jump, and a
        fresh region walks on along the valley (measured on the entry-point test's curve:
        stops at chi2 1166 / 1240 / 4347 from 1e-10 perturbations of the same data)."""
        for _ in range(N_POLISH):
            if res.status != 3:  # xtol: anything else is a converged or spent run
                break
            new = self._refine(res.x, max_nfev=max(1, self.max_nfev // 2))
            if new is None or new.cost >= res.cost * (1.0 - POLISH_GAIN):
                if new is not None and new.cost < res.cost:
                    res = new
                break
            res = new
        return res

    def _cost(self, x: NDArray[np.float64]) -> float:
        """Weighted sum of squares at ``x`` (inf once the evaluation budget is spent)."""
        left = self._remaining()
        if left is not None and left <= 0:
            return math.inf
        r = self._residual(x)
        return float(r @ r)

    def _profiled(self, x: NDArray[np.float64], window: float = PROFILE_WINDOW
                  ) -> tuple[float, NDArray[np.float64]]:
        """Cost at the best surface position within ``x[0] +- window`` and that start, from
        ONE model evaluation.

        On a linear approach ramp (rest gap falling at ``rate`` per unit time) moving the
        surface by ``s`` shifts the whole prediction in time by ``s / rate`` (the slow flow
        starts settled far from the surface and the lock-in filter is time-invariant), so one
        prediction along the ramp continued by ``window`` scores every shift: the narrow valley
        of the surface position (a fraction of a nanometre decides whether the tip reaches the
        contact) is searched in ``PROFILE_STEP`` steps for the price of one point. Without a
        linear ramp: the cost at ``x``.
        """
        v = self._values(x)
        rate = None if self._ramp is None else -(self._ramp[1] + v.get(DRIFT, 0.0))
        if rate is None or rate <= 0.0:
            return self._cost(x), x
        left = self._remaining()
        if left is not None and left <= 0:
            return math.inf, x
        slope, icpt, tm, am, pm = self._ramp[1:]
        h = self.model_.step
        # the ramp continued by ``window`` both ways: every shift reads a prediction of the
        # same history (a long-range term makes even the first point depend on the gap)
        pre = int(math.ceil(window / rate / h))
        n = int(math.ceil((tm[-1] + window / rate - tm[0]) / h)) + 1
        tau = tm[0] + h * np.arange(-pre, n)
        gap = (icpt + slope * (tau - tm[0]) - v[OFFSET]
               + v.get(DRIFT, 0.0) * (tau - self._curve.tau[0]))
        model = self._model(v)
        a, p = model.predict(self._law(v), tau, gap)
        self._count(model)
        lo, hi = self._offset_bounds
        s = np.arange(-window, window + 0.5 * PROFILE_STEP, PROFILE_STEP)
        s = s[(v[OFFSET] + s >= lo) & (v[OFFSET] + s <= hi)]
        if s.size == 0:
            return self._cost(x), x
        t = tm[None, :] + s[:, None] / rate
        ra = (np.interp(t, tau, a) - am) / self.sigma_[0]
        rp = wrap_phase(np.interp(t, tau, p) - pm) / self.sigma_[1]
        cost = np.sum(ra * ra + rp * rp, axis=1)
        cost = np.where(np.isfinite(cost), cost, math.inf)
        k = int(np.argmin(cost))
        y = x.copy()
        y[0] += s[k]
        best = float(cost[k])
        if 0 < k < s.size - 1 and np.all(np.isfinite(cost[k - 1:k + 2])):
            # the vertex of the parabola through the best shift and its neighbours
            cm, c0, cp = cost[k - 1:k + 2]
            curv = cm - 2.0 * c0 + cp
            if curv > 0.0:
                u = 0.5 * (cm - cp) / curv
                y[0] += u * PROFILE_STEP
                best = float(c0 - 0.25 * (cm - cp) * u)
        return best, y

    def predict(self, curve: Curve) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Amplitude (/ free amplitude) and lag [rad] of the whole curve, shape (m,) each."""
        return self._model(self.values_).predict(self.law_, curve.tau, self.gap(curve))

    def gap(self, curve: Curve, values: dict | None = None) -> NDArray[np.float64]:
        """Rest gap programme of ``curve`` under the fitted (or given) offset and drift."""
        v = self.values_ if values is None else values
        return curve.z_piezo - v[OFFSET] + v.get(DRIFT, 0.0) * (curve.tau - curve.tau[0])

    def chi2(self, curve: Curve, mask: NDArray[np.bool_]) -> float:
        """Weighted sum of squares of the fitted model on the points ``mask``."""
        a, p = self.predict(curve)
        ra = (a - curve.amplitude)[mask] / self.sigma_[0]
        rp = wrap_phase(p - curve.phase)[mask] / self.sigma_[1]
        return float(ra @ ra + rp @ rp)

    # ------------------------------------------------------------------ internals
    def _model(self, values: dict) -> SlowFlowModel:
        """The slow flow at drive frequency ``omega``, its drive giving the free amplitude
        ``free_scale`` (1 unless fitted)."""
        w = values[OMEGA]
        q = self.model_.quality_factor
        return SlowFlowModel(quality_factor=q, omega=w,
                             drive=values.get(FREE_SCALE, 1.0) * math.hypot(1.0 - w * w, w / q),
                             lockin=self.lockin, step=self.model_.step)

    def _values(self, x: NDArray[np.float64]) -> dict:
        out = {OFFSET: float(x[0]), OMEGA: float(x[1])}
        for p, xi in zip(self._params, x[2:], strict=True):
            out[p.field] = _dec(p, xi)
        return out

    def _law(self, values: dict) -> CurveLaw:
        return self._base.replace(**{k: v for k, v in values.items()
                                     if k not in (OFFSET, DRIFT, OMEGA, FREE_SCALE)})

    def _residual(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        c, e = self._curve, self._end
        m = self._mask[:e]
        v = self._values(x)
        model = self._model(v)
        a, p = model.predict(self._law(v), c.tau[:e], self.gap(c, v)[:e])
        self._count(model)
        ra = (a - c.amplitude[:e])[m] / self.sigma_[0]
        rp = wrap_phase(p - c.phase[:e])[m] / self.sigma_[1]
        out = np.concatenate([ra, rp])
        return np.where(np.isfinite(out), out, 1e6)

    def _set(self, x: NDArray[np.float64]) -> None:
        self.values_ = self._values(x)
        self.law_ = self._law(self.values_)
        self.offset_ = self.values_[OFFSET]
        self.drift_ = self.values_.get(DRIFT, 0.0)

    def _start(self, curve: Curve, params: list[Parameter]) -> list[list[NDArray[np.float64]]]:
        """Start vectors by far basin (``far_basins``; one list without a far term): around
        the given start the ``n_starts`` best-scored candidates of each basin, else the
        ``n_starts`` best points of a scan of the offset and the baseline's scales."""
        app = curve.segment == 0
        sel = app & (curve.amplitude > 0.2) & (curve.amplitude < 0.9)
        guess = (float(np.median(curve.z_piezo[sel] - curve.amplitude[sel])) if sel.any()
                 else float(np.min(curve.z_piezo[app])))
        # a curve whose amplitude never falls below 0.9 of free may not have met the surface at
        # all: the surface may then stay out of reach (else the model's tip must touch within
        # 0.6 free amplitudes and makes a dip the data do not have; A's flat Asylum curves)
        reach = 0.6 if sel.any() else OUT_OF_REACH
        self._offset_bounds = (guess - reach, guess + 0.6)
        if self.start is not None:
            x = [self.start.get(OFFSET, guess), self.start.get(OMEGA, self.model_.omega)]
            x += [_enc(p, self.start.get(p.field, p.init)) for p in params]
            x = np.array(x)
            # every combination of the new parameters' starting values, each with the
            # attraction and stiffness rescaled
            cands = self._rescaled(x, params, with_identity=True)
            if len(cands) == 1:
                return [[cands[0][1]]]
            # each candidate at its best surface position (a new term moves the surface the
            # data imply: a damping or an attraction lowers the amplitude like a nearer surface)
            scored = [(b, *self._profiled(c)) for b, c in cands]
            out = []
            for b in sorted({b for b, _ in cands}):
                mine = [(c, y) for k, c, y in scored if k == b]
                costs = np.array([c for c, _ in mine])
                order = np.argsort(costs, kind="stable")[: self.n_starts]
                out.append([mine[int(i)][1] for i in order])
            return out
        scan = []
        tail = [_enc(p, p.init) for p in params[2:]]
        coarse = ((1e-6, 1e-5, 1e-4), (1.0, 30.0, 1000.0))
        fine_scales = FINE_SCALES
        if self._ramp is not None:
            # each point costs one evaluation, not one per surface position: denser grids
            # (where the model jumps to the repulsive branch turns on ~20 % of attraction)
            offsets = (guess,)  # profiled over +-COARSE_WINDOW
            if not sel.any():  # and a start whose closest rest gap keeps the tip clear
                offsets = (guess, guess - 0.5 * OUT_OF_REACH)
            coarse, fine_scales = PROFILED_COARSE, PROFILED_FINE_SCALES
        else:
            offsets = (guess - 0.05, guess, guess + 0.05) if self.n_starts == 1 else \
                tuple(guess + np.linspace(-0.1, 0.1, 5))
            if not sel.any():
                offsets += (guess - 0.5 * OUT_OF_REACH,)
        for off in offsets:
            for vdw in coarse[0]:
                for e in coarse[1]:
                    x = np.array([off, self.model_.omega, math.log10(vdw), math.log10(e)]
                                 + tail)
                    c, y = self._profiled(x, COARSE_WINDOW)
                    scan.append((c, len(scan), y))
        # a fine grid around the coarse scan's best: surface position jointly with the
        # attraction and the stiffness (the valley is narrow and correlated: whether the model's
        # tip reaches the contact turns on a fraction of a nanometre)
        x0 = min(scan, key=lambda t: (t[0], t[1]))[2]
        fine = []
        # with a linear ramp the surface position is profiled at every grid point
        for dx in ((0.0,) if self._ramp is not None else FINE_OFFSETS):
            for fv in fine_scales[0]:
                for fs in fine_scales[1]:
                    y = x0.copy()
                    y[0] += dx
                    y[2] += math.log10(fv)
                    y[3] += math.log10(fs)
                    if not np.array_equal(y, x0):
                        fine.append(y)
        if self.max_evaluations is not None:
            # at most a third of the budget: a sparser grid (every k-th point)
            k = math.ceil(len(fine) / max(1, self.max_evaluations // 3))
            fine = fine[::k]
        for y in fine:
            c, y = self._profiled(y)
            scan.append((c, len(scan), y))
        scan.sort(key=lambda t: (t[0], t[1]))
        out = _distinct([x for _, _, x in scan], self.n_starts + N_EXTRA_STARTS)
        # the coarse scan's best is refined too (the fine grid's best may sit in a narrower
        # valley): the better fit is kept
        if not any(np.array_equal(x0, x) for x in out):
            out.append(x0)
        return [out]

    def _far_law_from_data(self, x: NDArray[np.float64], *, decay: float | None = None
                           ) -> tuple[float, float] | None:
        """``(coefficient, decay length)`` of a far damping term read off the fitted approach
        points at rest gaps beyond ``FAR_GAP`` (under ``x``'s surface position), where the
        amplitude follows the steady state ``s |D0| / |1 - W**2 + i W (1/Q + c exp(-z/l))|``
        (``s`` the free-amplitude scale); None with too few points or no loss found.
        ``decay`` (/ free amplitude): that decay held, only the coefficient read.

        A start, not a fit: one model evaluation cannot walk from a far term of the wrong decay
        (measured: a 2-3 um decay on a 1.2 um ramp, the fit from 500 nm stalled at chi2
        12000-15000 against ~410 from the truth)."""
        v = self._values(x)
        c = self._curve
        idx = np.flatnonzero(self._mask & (c.segment == 0))
        gap = self.gap(c, v)[idx]
        sel = gap > FAR_GAP
        if np.count_nonzero(sel) < 10:
            return None
        z, a = gap[sel], c.amplitude[idx][sel]
        w, q = v[OMEGA], self.model_.quality_factor
        d0 = math.hypot(1.0 - w * w, w / q)
        p = {p.field: p for p in self._params}
        lo_l, hi_l = (math.log10(p["far_decay_length"].low), math.log10(p["far_decay_length"].high))

        def resid(y: NDArray[np.float64]) -> NDArray[np.float64]:
            g = 10.0 ** y[1] * np.exp(-z / 10.0 ** y[2])
            return y[0] * d0 / np.hypot(1.0 - w * w, w * (1.0 / q + g)) - a

        best = None
        if decay is not None:
            ld = math.log10(decay)
            res = optimize.least_squares(lambda y: resid(np.array([y[0], y[1], ld])),
                                         np.array([1.0, math.log10(0.1 / q)]),
                                         bounds=([0.9, -8.0], [3.0, -1.0]))
            best = res
            best.x = np.array([res.x[0], res.x[1], ld])
        for length in () if decay is not None else (0.5, 2.0, 5.0):  # decays tried [um]
            y0 = np.array([1.0, math.log10(0.1 / q), min(max(math.log10(
                length * 1e-6 / c.length_m), lo_l + 1e-6), hi_l - 1e-6)])
            res = optimize.least_squares(resid, y0, bounds=([0.9, -8.0, lo_l], [3.0, -1.0, hi_l]))
            if best is None or res.cost < best.cost:
                best = res
        coef, decay = 10.0 ** best.x[1], 10.0 ** best.x[2]
        # a loss that the far points do not show (below a thousandth of the lever's own)
        if coef * math.exp(-float(np.min(z)) / decay) < 1e-3 / q:
            return None
        return coef, decay

    def _far_starts(self, x: NDArray[np.float64], params: list[Parameter], *,
                    data: bool) -> list[list[tuple[float, float]]]:
        """Starts ``(coefficient, decay length)`` (encoded) of the far damping term, one list
        per basin of ``far_basins``; without ``data`` only the basins that read nothing off the
        data (``LeverFarStart``: a refinement from a fit's own solution)."""
        return [b.starts(self, x, params) if data or isinstance(b, LeverFarStart) else []
                for b in self.far_basins]

    def _free_scale_start(self, x: NDArray[np.float64]) -> float:
        """Free-amplitude scale that makes the steady amplitude at the first rest gap 1 under
        the damping of ``x``: ``|1 - W**2 + i W (1/Q + g)| / |1 - W**2 + i W / Q|`` with
        ``g`` the damping terms' coefficient at that gap (a far term barely changes over one
        oscillation)."""
        v = self._values(x)
        law = self._law(v)
        z0 = float(self.gap(self._curve, v)[0])
        g = sum(c * math.exp(-z0 / zb) for _, c, zb in law.damping_terms())
        w, q = v[OMEGA], self.model_.quality_factor
        return math.hypot(1.0 - w * w, w * (1.0 / q + g)) / math.hypot(1.0 - w * w, w / q)

    def _rescaled(self, x: NDArray[np.float64], params: list[Parameter], *,
                  with_identity: bool) -> list[tuple[int, NDArray[np.float64]]]:
        """Candidates around ``x`` as ``(basin, vector)``: the hypothesis' parameters at each of
        their starting values (the start's or ``init``, then ``alternatives``) times the
        ``rescales`` of ``vdw`` and ``stiffness``; a changed contact exponent keeps the force
        at ``DELTA_REF``. ``basin``: the index in ``far_basins`` of the far term's start (0
        without a far term)."""
        idx = {p.field: 2 + i for i, p in enumerate(params)}
        extra = [p for p in params if p.field not in ("vdw", "stiffness")]
        # a free-amplitude scale not given by the start: the one that puts the model's
        # amplitude at the ramp's start at 1 under each combination's damping
        scale = FREE_SCALE in idx and FREE_SCALE not in (self.start or {})
        # one choice per parameter (its values, encoded), the far term's coefficient and decay
        # as one joint choice (``_far_starts``)
        groups: list[tuple[tuple[str, ...], list[tuple[float, ...]]]] = []
        basin_of: dict[tuple[float, ...], int] = {}
        for p in extra:
            if p.field == "far_decay_length" and "far_damping" in idx:
                continue
            if p.field == "far_damping" and "far_decay_length" in idx:
                starts = []
                for b, pairs in enumerate(self._far_starts(x, params, data=scale)):
                    for pair in pairs:
                        if pair not in basin_of:
                            basin_of[pair] = b
                            starts.append(pair)
                groups.append((("far_damping", "far_decay_length"), starts))
                continue
            xi = float(x[idx[p.field]])
            groups.append(((p.field,), [(xi,)] + [(_enc(p, a),) for a in p.alternatives
                                                  if _enc(p, a) != xi]))
        # the exponent the given stiffness belongs to
        e0 = (self.start or {}).get("exponent", self._base.exponent)
        out = []
        far = [i for i, (f, _) in enumerate(groups) if f == ("far_damping", "far_decay_length")]
        for combo in itertools.product(*(values for _, values in groups)):
            basin = basin_of[combo[far[0]]] if far else 0
            y = x.copy()
            for (fields, _), vals in zip(groups, combo, strict=True):
                for f, v in zip(fields, vals, strict=True):
                    y[idx[f]] = v
            if scale:
                p = params[idx[FREE_SCALE] - 2]
                y[idx[FREE_SCALE]] = _enc(p, min(max(self._free_scale_start(y), p.low),
                                                 p.high))
            de = 0.0
            if "exponent" in idx:
                de = e0 - y[idx["exponent"]]
            for fv, fs in self.rescales or ((1.0, 1.0),):
                z = y.copy()
                z[idx["vdw"]] += math.log10(fv)
                z[idx["stiffness"]] += math.log10(fs) + de * math.log10(DELTA_REF)
                out.append((basin, z))
        if not with_identity:
            out = [(b, z) for b, z in out if not np.allclose(z, x)]
        elif not any(np.allclose(z, x) for _, z in out):
            out.insert(0, (0, x.copy()))
        return out


def _distinct(xs: list[NDArray[np.float64]], k: int) -> list[NDArray[np.float64]]:
    """The first ``k`` of ``xs`` (best first) that differ from every one kept before by more
    than ``DISTINCT`` in some coordinate (offset / free amplitude, drive frequency, log10 of
    the law's scales): near-tied scan points in one valley are refined once, and the next
    starts come from other valleys."""
    out: list[NDArray[np.float64]] = []
    for x in xs:
        tol = np.full(x.size, DISTINCT[2])
        tol[:2] = DISTINCT[:2]
        if all(np.max(np.abs(x - y) / tol) > 1.0 for y in out):
            out.append(x)
            if len(out) == k:
                break
    return out


def _linear_ramp(curve: Curve, mask: NDArray[np.bool_]):
    """``(t0, slope, intercept, tau, amplitude, phase)`` of the fitted points when they lie on
    one approach segment whose piezo positions follow a line (rms deviation below
    ``RAMP_TOLERANCE``), else None (the surface profile is not used)."""
    idx = np.flatnonzero(mask)
    if idx.size < 3 or not np.all(curve.segment[idx] == 0):
        return None
    tm = curve.tau[idx]
    slope, icpt = np.polyfit(tm - tm[0], curve.z_piezo[idx], 1)
    dev = curve.z_piezo[idx] - (icpt + slope * (tm - tm[0]))
    if not (slope < 0.0 and math.sqrt(float(np.mean(dev * dev))) < RAMP_TOLERANCE):
        return None
    return (float(tm[0]), float(slope), float(icpt), tm, curve.amplitude[idx],
            curve.phase[idx])


def _far_parameters(params: list[Parameter]) -> tuple[Parameter, Parameter]:
    """The far damping's coefficient and decay parameters among ``params``."""
    p = {q.field: q for q in params}
    return p["far_damping"], p["far_decay_length"]


def _far_coordinates(x: NDArray[np.float64], params: list[Parameter]
                     ) -> tuple[Parameter, float, float]:
    """The far coefficient's parameter and ``x``'s encoded far coefficient and decay."""
    idx = {p.field: 2 + i for i, p in enumerate(params)}
    return (params[idx["far_damping"] - 2], float(x[idx["far_damping"]]),
            float(x[idx["far_decay_length"]]))


def _enc(p: Parameter, v: float) -> float:
    return math.log10(v) if p.log else float(v)


def _dec(p: Parameter, x: float) -> float:
    return 10.0 ** float(x) if p.log else float(x)


def wrap_phase(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """Phase differences [rad] wrapped to ``[-pi, pi)``, same shape as ``d``."""
    return (d + np.pi) % (2.0 * np.pi) - np.pi
