"""Output-error refinement: fit the model's own periodic orbit to the measured one.

The harmonic balance (:mod:`.balance`) evaluates the force on the *measured* orbit and
linearises the noise; for forces that jump (a neck that snaps, a rate term switched on at
contact) that linearisation fails and a small equation error can hide a large orbit error. This
stage removes the approximation: for each parameter vector the model's periodic orbit is found
by Newton shooting on the one-period map of the compiled RK4 kernel, and its harmonics are
compared with the measured ones in units of their noise (plus the calibration priors). The
chi-square of this residual is the likelihood of "measured = model orbit + white noise", so the
evidence and the held-out simulation judge the same thing.

Joint fits: every observation's orbit is shot with its own gap and drive phase 0; its drive
phase is then projected out in closed form (:func:`align_phase`): with drive
``B cos(Omega tau - phi)`` the steady orbit is the phase-0 orbit delayed by ``phi / Omega``,
so its harmonics are ``X_n e^{-i n phi}`` and the best ``phi`` (with the recorded phase's
prior, if any) is a one-dimensional trigonometric problem. The shared parameters are refined
by least squares on the projected residual (variable projection).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from afmlearn.preprocess.phase import align_phase
from simulator import Scales

from ._kernel import simulate_model
from .balance import Solution, harmonics, to_real
from .hypotheses.base import Parameter
from .joint import JointBalance
from .model import DiagnosisModel
from .spec import ModelSpec

__all__ = ["periodic_orbit", "OutputError", "align_phase", "settle_periods", "start_state"]

FloatArray = NDArray[np.float64]


def periodic_orbit(model: DiagnosisModel, state0: FloatArray, attached0: bool, *,
                   n_out: int = 1024, max_iter: int = 12, tol: float = 1e-10,
                   settle_periods: int = 0, multipliers: list | None = None,
                   jacobian: FloatArray | None = None, state_out: list | None = None
                   ) -> tuple[FloatArray, FloatArray, bool]:
    """The model's periodic orbit through (near) ``state0`` at ``tau = 0``.

    Newton shooting on the one-period map ``P(s) - s = 0`` (finite-difference monodromy),
    integrated with ``n_out`` RK4 steps per period: chord iterations with ``jacobian`` (a
    monodromy estimate from a nearby model, overwritten in place with the last one used), then
    full Newton. If both fail and ``settle_periods > 0``, the model is integrated that many
    periods from ``state0`` and its last period is returned (its attractor, if it settled).

    Returns the true deflection and rate at ``n_out`` equally spaced phases
    ``theta = 2 pi k / n_out`` and whether shooting converged. If ``multipliers`` is a list,
    the Floquet multipliers of the converged orbit are appended to it (all of modulus < 1: a
    stable orbit). If ``state_out`` is a list, the orbit's state ``[q1, q1', q2, q2']`` and
    neck state at ``tau = 0`` are appended to it.
    """
    T = 2 * math.pi / model.omega
    args = model.kernel_args()
    dim = 4 if model.spec.extra_mode is not None else 2
    att = bool(attached0)

    last: dict[str, FloatArray] = {}

    def period_map(x: FloatArray) -> tuple[FloatArray, bool]:
        full = np.zeros(4)
        full[:dim] = x
        # sampled at every step: the last call's samples are the orbit once Newton stops
        out, end, a = simulate_model(full, att, 0.0, T / n_out, n_out, 1, *args)
        last["x"], last["out"] = x.copy(), out
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
    if state_out is not None:
        state_out.append((full.copy(), att))
    if ok and "x" in last and np.array_equal(last["x"], x):
        out = last["out"]
    else:
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


def settle_periods(model: DiagnosisModel, *, cap: int = 3000) -> int:
    """Drive periods for the slowest mode's transient to fall by e^-9 (~1e-4)."""
    d = [float(model.coef[1])]
    if model.spec.extra_mode is not None:
        d.append(model.spec.extra_mode.modal()[1])
    rate = max(min(d), 1e-6) / 2.0          # amplitude decay rate per unit tau
    return int(min(math.ceil(9.0 / rate * model.omega / (2 * math.pi)), cap))


def start_state(model: DiagnosisModel, orbit, phase: float) -> tuple[FloatArray, bool]:
    """State ``[q1, q1', q2, q2']`` and neck state at ``tau = 0`` of the phase-0 model, taken
    from the measured orbit ``phase`` radians into its period (where the phase-0 orbit
    starts when the measured one has drive phase ``phase``)."""
    at = DiagnosisModel(spec=model.spec.replace(drive_phase=float(phase)), coef=model.coef,
                        omega=model.omega, gap=model.gap, scales=model.scales)
    x, v, _ = orbit.true_orbit(model.spec)
    q2, q2d = at.mode2_orbit(orbit)
    k = int(round(float(np.mod(phase, 2 * np.pi)) / (2 * np.pi) * orbit.grid)) % orbit.grid
    att = model.spec.state(model.gap - x)
    return np.array([x[k] - q2[k], v[k] - q2d[k], q2[k], q2d[k]]), bool(att[k])


class OutputError:
    """Output-error least squares of one model structure against the measured orbits.

    Parameters
    ----------
    jb : JointBalance
        Gives the measured orbits, their noise, the calibration and phase priors.
    scales : simulator.Scales
        SI scales of the models built.
    n_out : int
        RK4 steps (and output samples) per period of the shooting.
    """

    def __init__(self, jb: JointBalance, scales: Scales, *, n_out: int = 256) -> None:
        self.jb = jb
        self.scales = scales
        self.n_out = int(n_out)
        self._orbits = [hb.orbit for hb in jb.balances]
        self._y_real = [to_real(o.Y) for o in self._orbits]
        self._sigma = [o.sigma_rows for o in self._orbits]
        self._warm: dict[tuple, tuple[FloatArray, bool]] = {}
        self._jac: dict[tuple, FloatArray] = {}
        self._phases = [0.0] * jb.n_obs
        #: settle runs (instead of shooting) still allowed in the current refinement
        self._settle_budget = 0

    def snapshot(self) -> tuple[dict, dict, list[float]]:
        """The shooting warm starts, monodromy estimates and phases, to :meth:`restore`."""
        return (dict(self._warm), {k: v.copy() for k, v in self._jac.items()},
                list(self._phases))

    def restore(self, state: tuple[dict, dict, list[float]]) -> None:
        """Warm starts of a :meth:`snapshot`: a model's periodic orbit is then shot from the
        orbits of the fit that took the snapshot. Where two stable orbits coexist at a
        set-point (attractive and tapping branches) the start decides the branch, so a fit's
        held-out refits must start from its own orbits, not from whatever was fitted last."""
        warm, jac, phases = state
        self._warm = dict(warm)
        self._jac = {k: v.copy() for k, v in jac.items()}
        self._phases = list(phases)

    def subset(self, indices: Sequence[int]) -> OutputError:
        """The output error of some observations (held-out folds), warm starts kept."""
        oe = OutputError(self.jb.subset(indices), self.scales, n_out=self.n_out)
        for new, old in enumerate(indices):
            for (i, key), v in self._warm.items():
                if i == old:
                    oe._warm[(new, key)] = v
        return oe

    @staticmethod
    def _key(spec: ModelSpec) -> tuple:
        return spec.state_key

    def model(self, i: int, spec: ModelSpec, coef: FloatArray, phase: float = 0.0
              ) -> DiagnosisModel:
        """The model at observation ``i`` (its gap, drive frequency and its drive group's
        amplitude ``B``; ``coef`` the joint vector, :mod:`~afmlearn.diagnose.joint`) with
        drive ``phase``."""
        o = self._orbits[i]
        return DiagnosisModel(spec=spec.replace(drive_phase=float(phase)),
                              coef=self.jb.observation_coef(i, spec, coef), omega=o.omega,
                              gap=o.gap, scales=self.scales)

    def start(self, i: int, model0: DiagnosisModel) -> tuple[FloatArray, bool]:
        """Shooting start for the phase-0 model at observation ``i``: the last converged
        orbit of the same structure, else the measured orbit at the current phase."""
        key = (i, self._key(model0.spec))
        if key in self._warm:
            return self._warm[key]
        return start_state(model0, self._orbits[i], self._phases[i])

    def orbit(self, i: int, model0: DiagnosisModel, *, n_out: int | None = None,
              settle: int = 0, multipliers: list | None = None
              ) -> tuple[FloatArray, FloatArray, bool]:
        """Periodic orbit (true deflection, rate; ``n_out`` phases) of the phase-0 model."""
        s0, a0 = self.start(i, model0)
        dim = 4 if model0.spec.extra_mode is not None else 2
        jac = self._jac.setdefault((i, self._key(model0.spec)), np.full((dim, dim), np.nan))
        state: list = []
        x, v, ok = periodic_orbit(model0, s0, a0, n_out=n_out or self.n_out, max_iter=20,
                                  jacobian=jac, settle_periods=settle, multipliers=multipliers,
                                  state_out=state)
        if ok:
            self._warm[(i, self._key(model0.spec))] = state[0]
        return x, v, ok

    def residual(self, spec: ModelSpec, coef: FloatArray
                 ) -> tuple[FloatArray, bool, list[float]]:
        """Whitened orbit residuals of every observation (phases projected out), then the
        calibration-prior and phase-prior rows; whether every orbit converged; the phases."""
        parts = []
        ok_all = True
        phases = []
        prior = self.jb.prior_residual(coef)
        for i, o in enumerate(self._orbits):
            m0 = self.model(i, spec, coef)
            settle = settle_periods(m0) if self._settle_budget > 0 else 0
            x, _, ok = self.orbit(i, m0, settle=settle)
            if not ok:
                ok_all = False
                if not settle:   # no orbit at all: a point the refinement must step back from
                    n_ph = sum(p is not None for p in self.jb.phase_priors)
                    size = sum(s.size for s in self._sigma) + prior.size + n_ph
                    return np.full(size, 1e3), False, list(self._phases)
                self._settle_budget -= 1
            y = m0.measured(x)
            if not np.all(np.isfinite(y)):
                parts.append(np.full(self._sigma[i].size, 1e6))
                phases.append(self._phases[i])
                continue
            X0 = harmonics(y, o.n_h)
            ph = align_phase(X0, o.Y, float(self._sigma[i][1]), self.jb.phase_priors[i])
            n = np.arange(X0.size)
            parts.append((to_real(X0 * np.exp(-1j * n * ph)) - self._y_real[i])
                         / self._sigma[i])
            phases.append(ph)
        return (np.concatenate([*parts, prior, self.jb.phase_residual(phases)]), ok_all,
                phases)

    def refine(self, sol: Solution, build: Callable[[Sequence[float]], ModelSpec],
               params: Sequence[Parameter], *, max_nfev: int = 25) -> tuple[Solution, bool]:
        """Refine ``(K, D, B, c, *nonlinear values)`` from ``sol`` (any stage).

        ``build(values) -> ModelSpec`` maps the nonlinear values (``params`` order; the
        solution's ``values`` are the start) to a spec. Returns the refined solution (chi2 =
        output-error chi2, ``phases`` the projected ones) and whether its orbits converged.
        """
        if sol.phases:
            self._phases = list(sol.phases)
        self._settle_budget = 3
        lin = np.asarray(sol.coef, float)
        n_lin = lin.size
        lo_l, hi_l = self.jb.bounds(sol.spec)
        lo_n = np.array([_u(p, p.low) for p in params])
        hi_n = np.array([_u(p, p.high) for p in params])
        u_n = np.clip([_u(p, v) for p, v in zip(params, sol.values, strict=True)],
                      lo_n + 1e-9 * (hi_n - lo_n), hi_n - 1e-9 * (hi_n - lo_n))
        u_n = np.asarray(u_n, float).reshape(-1)
        lin0 = np.clip(lin, lo_l, hi_l)
        scale_l = np.maximum(np.abs(lin0), 1e-6 * max(float(np.max(np.abs(lin0))), 1e-9))
        x0 = np.concatenate([lin0 / scale_l, u_n])
        lo = np.concatenate([lo_l / scale_l, lo_n])
        hi = np.concatenate([hi_l / scale_l, hi_n])
        x0 = np.minimum(np.maximum(x0, lo), hi)
        best: dict[str, tuple] = {}

        def fun(x: FloatArray) -> FloatArray:
            vals = tuple(_from_u(p, float(v)) for p, v in zip(params, x[n_lin:], strict=True))
            spec = build(vals)
            coef = x[:n_lin] * scale_l
            r, ok, phases = self.residual(spec, coef)
            c2 = float(r @ r)
            if "b" not in best or c2 < best["b"][0]:
                # the orbits this point was shot to go with it: the warm starts are rewritten
                # by every later evaluation (finite-difference probes, rejected steps), and
                # where two orbits coexist at a set-point the start decides the branch
                best["b"] = (c2, coef.copy(), spec, ok, vals, r, phases, dict(self._warm))
                self._phases = list(phases)
            return r

        r0 = fun(x0)
        if np.all(r0 < 1e3):
            try:
                least_squares(fun, x0, bounds=(lo, hi), method="trf", x_scale="jac",
                              diff_step=1e-4, max_nfev=max_nfev)
            except np.linalg.LinAlgError:   # a singular step: keep the best point seen
                pass
        c2, coef, spec, ok, vals, r, phases, warm = best["b"]
        # leave the state at the solution returned (a snapshot taken now, the held-out refits
        # and the next refinement start from its own orbits: measured on a 1,000 spp detector
        # series, the last probe's orbits gave chi2 1.4e6 at a point fitted to 7,333)
        self._warm.update(warm)             # (its phases were set when it became the best)
        return Solution(spec=spec, coef=coef, residual=r, chi2=c2, values=vals,
                        phases=tuple(phases)), ok


def _u(p: Parameter, v: float) -> float:
    return math.log(v) if p.log else v


def _from_u(p: Parameter, u: float) -> float:
    return math.exp(u) if p.log else u
