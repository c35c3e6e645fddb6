"""Output-error refinement: fit the model's own periodic orbit to the measured one.

The harmonic balance (:mod:`.balance`) evaluates the force on the *measured* orbit and
linearises the noise; for forces that jump (a neck that snaps, a rate term switched on at
contact) that linearisation fails and a small equation error can hide a large orbit error. This
stage removes the approximation: for each parameter vector the model's periodic orbit is found
by Newton shooting on the one-period map of the compiled RK4 kernel, and its harmonics are
compared with the measured ones in units of their noise (plus the calibration priors). The
chi-square of this residual is the likelihood of "measured = model orbit + white noise", so the
evidence and the held-out simulation judge the same thing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from simulator import Scales

from ._kernel import simulate_model
from .balance import HarmonicBalance, Solution, harmonics, to_real
from .hypotheses.base import Parameter
from .model import DiagnosisModel
from .spec import ModelSpec, neck_state

__all__ = ["periodic_orbit", "OutputError"]

FloatArray = NDArray[np.float64]


def periodic_orbit(model: DiagnosisModel, state0: FloatArray, attached0: bool, *,
                   n_out: int = 1024, max_iter: int = 12, tol: float = 1e-10,
                   settle_periods: int = 0, multipliers: list | None = None,
                   jacobian: FloatArray | None = None) -> tuple[FloatArray, FloatArray, bool]:
    """The model's periodic orbit through (near) ``state0`` at ``tau = 0``.

    Newton shooting on the one-period map ``P(s) - s = 0`` (finite-difference monodromy),
    integrated with ``n_out`` RK4 steps per period: chord iterations with ``jacobian`` (a
    monodromy estimate from a nearby model, overwritten in place with the last one used), then
    full Newton. If both fail and ``settle_periods > 0``, the model is integrated that many
    periods from ``state0`` and its last period is returned (its attractor, if it settled).

    Returns the true deflection and rate at ``n_out`` equally spaced phases
    ``theta = 2 pi k / n_out`` and whether shooting converged. If ``multipliers`` is a list,
    the Floquet multipliers of the converged orbit are appended to it (all of modulus < 1: a
    stable orbit).
    """
    T = 2 * math.pi / model.omega
    args = model.kernel_args()
    dim = 4 if model.spec.mode2 is not None else 2
    att = bool(attached0)

    def period_map(x: FloatArray) -> tuple[FloatArray, bool]:
        full = np.zeros(4)
        full[:dim] = x
        _, end, a = simulate_model(full, att, 0.0, T, 1, n_out, *args)
        return end[:dim], a

    x0 = np.array(state0, float)[:dim]
    J0 = (jacobian.copy() if jacobian is not None and jacobian.shape == (dim, dim)
          and np.all(np.isfinite(jacobian)) else None)
    x, J, ok = _newton(period_map, x0, J0, max_iter, tol, chord=J0 is not None)
    if not ok and J0 is not None:
        x, J, ok = _newton(period_map, x0, None, max_iter, tol, chord=False)
    if jacobian is not None and J is not None and jacobian.shape == J.shape:
        jacobian[...] = J
    full = np.zeros(4)
    full[:dim] = x
    if not ok and settle_periods > 0:
        full = np.zeros(4)
        full[:dim] = x0
        _, full, att = simulate_model(full, att, 0.0, T, int(settle_periods), n_out, *args)
    out, _, _ = simulate_model(full, att, 0.0, T / n_out, n_out, 1, *args)
    if multipliers is not None and ok:
        px, _ = period_map(x)
        multipliers.extend(np.linalg.eigvals(_monodromy(period_map, x, px,
                                                        max(float(np.max(np.abs(x))), 1e-3))))
    return out[0], out[1], ok and bool(np.all(np.isfinite(out)))


def _newton(period_map, x0: FloatArray, J: FloatArray | None, max_iter: int, tol: float, *,
            chord: bool) -> tuple[FloatArray, FloatArray | None, bool]:
    """Solve ``P(x) = x``; ``chord``: keep ``J`` while the residual falls tenfold per step."""
    x = x0.copy()
    dim = x.size
    last = math.inf
    for _ in range(max_iter):
        px, _ = period_map(x)
        r = px - x
        if not np.all(np.isfinite(r)):
            return x, J, False
        scale = max(float(np.max(np.abs(x))), 1e-3)
        err = float(np.max(np.abs(r)))
        if err < tol * scale:
            return x, J, True
        if J is None or not chord or err > 0.1 * last:
            J = _monodromy(period_map, x, px, scale)
        last = err
        try:
            step = np.linalg.solve(J - np.eye(dim), -r)
        except np.linalg.LinAlgError:
            return x, J, False
        # damp steps that would leave the neighbourhood of the measured orbit
        lim = 0.2 * scale
        m = float(np.max(np.abs(step)))
        if m > lim:
            step *= lim / m
        x = x + step
    return x, J, False


def _monodromy(period_map, x: FloatArray, px: FloatArray, scale: float) -> FloatArray:
    """Finite-difference Jacobian of the one-period map at ``x`` (``px = P(x)``)."""
    dim = x.size
    J = np.empty((dim, dim))
    for j in range(dim):
        h = 1e-7 * max(abs(x[j]), scale * (0.1 if j % 2 == 0 else 1.0))
        xp = x.copy()
        xp[j] += h
        J[:, j] = (period_map(xp)[0] - px) / h
    return J


class OutputError:
    """Output-error least squares of one model structure against the measured orbit.

    Parameters
    ----------
    hb : HarmonicBalance
        Gives the measured orbit, its noise and the calibration priors.
    scales : simulator.Scales
        SI scales of the models built.
    n_out : int
        RK4 steps (and output samples) per period of the shooting.
    """

    def __init__(self, hb: HarmonicBalance, scales: Scales, *, n_out: int = 256) -> None:
        self.hb = hb
        self.scales = scales
        self.n_out = int(n_out)
        o = hb.orbit
        self._y_real = to_real(o.Y)
        self._sigma = o.sigma_rows
        self._warm: dict[tuple, tuple[FloatArray, bool]] = {}
        self._jac: dict[tuple, FloatArray] = {}
        #: settle runs (instead of shooting) still allowed in the current refinement
        self._settle_budget = 0

    @staticmethod
    def _key(model: DiagnosisModel) -> tuple:
        s = model.spec
        return (s.mode2 is not None, s.neck_length is not None, s.detector is not None)

    def _start(self, model: DiagnosisModel) -> tuple[FloatArray, bool]:
        """Shooting start: the last converged orbit of the same structure (the refinement moves
        in small steps), else the measured orbit's state at ``theta = 0``."""
        key = self._key(model)
        if key in self._warm:
            return self._warm[key]
        o = self.hb.orbit
        x, v, _ = o.true_orbit(model.spec)
        q2, q2d = model.mode2_orbit(o)
        att = neck_state(model.gap - x, model.spec.a0, model.spec.neck_length)
        return np.array([x[0] - q2[0], v[0] - q2d[0], q2[0], q2d[0]]), bool(att[0])

    @staticmethod
    def settle_periods(model: DiagnosisModel, *, cap: int = 3000) -> int:
        """Drive periods for the slowest mode's transient to fall by e^-9 (~1e-4)."""
        d = [float(model.coef[1])]
        if model.spec.mode2 is not None:
            ratio, q2, _ = model.spec.mode2
            d.append(ratio / q2)
        rate = max(min(d), 1e-6) / 2.0          # amplitude decay rate per unit tau
        return int(min(math.ceil(9.0 / rate * model.omega / (2 * math.pi)), cap))

    def residual(self, model: DiagnosisModel) -> tuple[FloatArray, bool]:
        """Whitened orbit residual (harmonics) followed by the calibration-prior rows."""
        o = self.hb.orbit
        s0, a0 = self._start(model)
        key = self._key(model)
        dim = 4 if model.spec.mode2 is not None else 2
        jac = self._jac.setdefault(key, np.full((dim, dim), np.nan))
        settle = self.settle_periods(model) if self._settle_budget > 0 else 0
        x, v, ok = periodic_orbit(model, s0, a0, n_out=self.n_out, max_iter=20, jacobian=jac,
                                  settle_periods=settle)
        if not ok:
            if not settle:   # no orbit at all: a point the refinement must step back from
                return np.full(self._sigma.size + self.hb.prior_residual(model.coef).size,
                               1e3), False
            self._settle_budget -= 1
        if ok:
            q2, q2d = (np.zeros(1), np.zeros(1)) if model.spec.mode2 is None else \
                model.mode2_orbit(o)
            self._warm[key] = (np.array([x[0] - q2[0], v[0] - q2d[0], q2[0],
                                                      q2d[0]]), a0)
        y = model.measured(x)
        if not np.all(np.isfinite(y)):
            r = np.full(self._sigma.size, 1e6)
        else:
            r = (to_real(harmonics(y, o.n_h)) - self._y_real) / self._sigma
        return np.concatenate([r, self.hb.prior_residual(model.coef)]), ok

    def refine(self, sol: Solution, build: Callable[[Sequence[float]], ModelSpec],
               params: Sequence[Parameter], *, max_nfev: int = 25) -> tuple[Solution, bool]:
        """Refine ``(K, D, B, c, *nonlinear values)`` from an equation-error solution.

        ``build(values) -> ModelSpec`` maps the nonlinear values (``params`` order; the
        solution's ``values`` are the start) to a spec. Returns the refined solution (chi2 =
        output-error chi2) and whether its orbit converged.
        """
        values = sol.values
        self._settle_budget = 3
        hb = self.hb
        lin = np.asarray(sol.coef, float)
        n_lin = lin.size
        lo_l, hi_l = hb.bounds(sol.spec)
        lo_n = np.array([_u(p, p.low) for p in params])
        hi_n = np.array([_u(p, p.high) for p in params])
        u_n = np.clip([_u(p, v) for p, v in zip(params, values, strict=True)],
                      lo_n + 1e-9 * (hi_n - lo_n), hi_n - 1e-9 * (hi_n - lo_n))
        u_n = np.asarray(u_n, float).reshape(-1)
        lin0 = np.clip(lin, lo_l, hi_l)
        scale_l = np.maximum(np.abs(lin0), 1e-6 * max(float(np.max(np.abs(lin0))), 1e-9))
        # linear coefficients pinned at a sign bound stay free to leave it
        x0 = np.concatenate([lin0 / scale_l, u_n])
        lo = np.concatenate([lo_l / scale_l, lo_n])
        hi = np.concatenate([hi_l / scale_l, hi_n])
        x0 = np.minimum(np.maximum(x0, lo), hi)
        o = self.hb.orbit
        omega, gap, scales = o.omega, o.gap, self.scales
        best: dict[str, tuple[float, FloatArray, ModelSpec, bool, tuple[float, ...]]] = {}

        def fun(x: FloatArray) -> FloatArray:
            vals = tuple(_from_u(p, float(v)) for p, v in zip(params, x[n_lin:], strict=True))
            m = DiagnosisModel(spec=build(vals), coef=x[:n_lin] * scale_l, omega=omega,
                               gap=gap, scales=scales)
            r, ok = self.residual(m)
            c2 = float(r @ r)
            if "b" not in best or c2 < best["b"][0]:
                best["b"] = (c2, m.coef.copy(), m.spec, ok, vals)
            return r

        r0 = fun(x0)
        if np.all(np.isfinite(r0)):
            try:
                least_squares(fun, x0, bounds=(lo, hi), method="trf", x_scale="jac",
                              diff_step=1e-4, max_nfev=max_nfev)
            except (ValueError, np.linalg.LinAlgError):
                pass
        c2, coef, spec, ok, vals = best["b"]
        model_r, _ = self.residual(DiagnosisModel(spec=spec, coef=coef, omega=omega, gap=gap,
                                                  scales=scales))
        return Solution(spec=spec, coef=coef, residual=model_r, chi2=c2, values=vals), ok


def _u(p: Parameter, v: float) -> float:
    return math.log(v) if p.log else v


def _from_u(p: Parameter, u: float) -> float:
    return math.exp(u) if p.log else u
