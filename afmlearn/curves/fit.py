"""Fit one tip--sample law to the approach branch of a lock-in curve (weighted least squares)."""

from __future__ import annotations

import logging
import math
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from simulator.lockin import LockIn

from .curve import Curve
from .hypotheses import BASELINE, DRIFT, Hypothesis, Parameter
from .law import CurveLaw
from .model import SlowFlowModel

__all__ = ["CurveFitter", "OFFSET", "wrap_phase"]

log = logging.getLogger(__name__)

#: name of the surface position (piezo coordinate where the rest gap is zero)
OFFSET = "offset"
#: name of the drive frequency / f0 (a nuisance: the free phase is biased by long-range forces)
OMEGA = "omega"
#: floors of the residual weights (amplitude / free amplitude, phase [rad])
_SIGMA_FLOOR = (1e-3, math.radians(0.05))


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
    """

    def __init__(self, *, hypothesis: Hypothesis | None = None, a0_m: float = 0.3e-9,
                 tip_radius_m: float = 10e-9, lockin: LockIn | None = None,
                 max_nfev: int = 60, start: dict | None = None,
                 step: float = 4.0 * math.pi, n_starts: int = 1) -> None:
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

    # ------------------------------------------------------------------ public API
    def fit(self, curve: Curve, *, mask: NDArray[np.bool_] | None = None) -> CurveFitter:
        """Fit on the points ``mask`` (default: the approach, ``segment == 0``)."""
        mask = curve.segment == 0 if mask is None else np.asarray(mask, dtype=bool)
        self.model_ = SlowFlowModel.for_curve(curve, lockin=self.lockin, step=self.step)
        self.sigma_ = tuple(max(s, f) for s, f in zip(curve.noise(), _SIGMA_FLOOR, strict=True))
        self._curve, self._mask = curve, mask
        self._base = CurveLaw(a0=self.a0_m / curve.length_m,
                              radius=self.tip_radius_m / curve.length_m)
        params = list(BASELINE.parameters)
        if self.hypothesis is not None:
            params += list(self.hypothesis.parameters)
        self._params = params
        starts = self._start(curve, params)
        w0 = self.model_.omega
        lo = np.array([self._offset_bounds[0], w0 - 0.005] + [_enc(p, p.low) for p in params])
        hi = np.array([self._offset_bounds[1], w0 + 0.005] + [_enc(p, p.high) for p in params])
        best = None
        for x0 in starts:
            x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
            res = optimize.least_squares(self._residual, x0, bounds=(lo, hi), method="trf",
                                         x_scale="jac", diff_step=1e-4,
                                         max_nfev=self.max_nfev)
            if best is None or res.cost < best.cost:
                best = res
        self._set(best.x)
        r = self._residual(best.x)
        self.chi2_ = float(r @ r)
        self.n_fit_ = int(r.size)
        return self

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
        w = values[OMEGA]
        q = self.model_.quality_factor
        return SlowFlowModel(quality_factor=q, omega=w, drive=math.hypot(1.0 - w * w, w / q),
                             lockin=self.lockin, step=self.model_.step)

    def _values(self, x: NDArray[np.float64]) -> dict:
        out = {OFFSET: float(x[0]), OMEGA: float(x[1])}
        for p, xi in zip(self._params, x[2:], strict=True):
            out[p.field] = _dec(p, xi)
        return out

    def _law(self, values: dict) -> CurveLaw:
        return self._base.replace(**{k: v for k, v in values.items()
                                     if k not in (OFFSET, DRIFT, OMEGA)})

    def _residual(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        c, m = self._curve, self._mask
        v = self._values(x)
        a, p = self._model(v).predict(self._law(v), c.tau, self.gap(c, v))
        ra = (a - c.amplitude)[m] / self.sigma_[0]
        rp = wrap_phase(p - c.phase)[m] / self.sigma_[1]
        out = np.concatenate([ra, rp])
        return np.where(np.isfinite(out), out, 1e6)

    def _set(self, x: NDArray[np.float64]) -> None:
        self.values_ = self._values(x)
        self.law_ = self._law(self.values_)
        self.offset_ = self.values_[OFFSET]
        self.drift_ = self.values_.get(DRIFT, 0.0)

    def _start(self, curve: Curve, params: list[Parameter]) -> list[NDArray[np.float64]]:
        """Start vectors: the given start, else the ``n_starts`` best points of a scan of the
        offset and the baseline's scales."""
        app = curve.segment == 0
        sel = app & (curve.amplitude > 0.2) & (curve.amplitude < 0.9)
        guess = (float(np.median(curve.z_piezo[sel] - curve.amplitude[sel])) if sel.any()
                 else float(np.min(curve.z_piezo[app])))
        self._offset_bounds = (guess - 0.6, guess + 0.6)
        if self.start is not None:
            x = [self.start.get(OFFSET, guess), self.start.get(OMEGA, self.model_.omega)]
            x += [_enc(p, self.start.get(p.field, p.init)) for p in params]
            cands = [np.array(x)]
            for i, p in enumerate(params):
                for alt in p.alternatives:
                    y = np.array(x)
                    y[2 + i] = _enc(p, alt)
                    cands.append(y)
            if len(cands) == 1:
                return cands
            costs = [float(r @ r) for r in map(self._residual, cands)]
            return [cands[int(np.argmin(costs))]]
        scan = []
        tail = [_enc(p, p.init) for p in params[2:]]
        offsets = (guess - 0.05, guess, guess + 0.05) if self.n_starts == 1 else \
            tuple(guess + np.linspace(-0.1, 0.1, 5))
        for off in offsets:
            for vdw in (1e-6, 1e-5, 1e-4):
                for e in (1.0, 30.0, 1000.0):
                    x = np.array([off, self.model_.omega, math.log10(vdw), math.log10(e)]
                                 + tail)
                    r = self._residual(x)
                    scan.append((float(r @ r), len(scan), x))
        scan.sort(key=lambda t: (t[0], t[1]))
        return [x for _, _, x in scan[: self.n_starts]]


def _enc(p: Parameter, v: float) -> float:
    return math.log10(v) if p.log else float(v)


def _dec(p: Parameter, x: float) -> float:
    return 10.0 ** float(x) if p.log else float(x)


def wrap_phase(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """Phase differences [rad] wrapped to ``[-pi, pi)``, same shape as ``d``."""
    return (d + np.pi) % (2.0 * np.pi) - np.pi
