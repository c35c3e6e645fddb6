"""Plain-Python reference integrator: ``scipy.integrate.solve_ivp`` between located events.

This is the slow, independent reference the compiled :class:`~simulator.integrate.RK4` is
checked against, and the baseline of the benchmarks. It integrates the same modal equations
(``physics.md`` §2, ``_kernel._rhs``)

    q_i'' + D_i(regime) q_i' + K_i q_i = dc_i cos(theta) + ds_i sin(theta) - s_i F_ts(z, z')
    z = g + g' (tau - tau_0) - sum_i q_i - y sin(theta),   theta = theta_0 + Omega (tau - tau_0)

but evaluates the tip--sample force with the force model's NumPy reference
(``model(z, zdot, contact)``), not with the canonical coefficient vector of the compiled kernel.
The five work integrals are extra ODE components (same columns as ``State.work``).

Regime switches are terminal ``solve_ivp`` events: out of contact ``z - a0`` falling, in
contact ``z - (a0 - break_indentation)`` rising (the hysteretic JKR neck). After each event the
integration restarts from the event state with the switched regime; samples are read from the
dense output of each smooth piece.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, final

import numpy as np
from scipy.integrate import solve_ivp

from ..system import System
from ._kernel import EVENT_TOL, N_WORK
from .base import AbstractIntegrator
from .state import Segment, State

__all__ = ["SolveIVP"]

_METHODS = ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA")
#: regime switches allowed per output sample before the run is declared chattering
_MAX_EVENTS_PER_SAMPLE = 8


def _positive(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number > 0, got {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return v


@final
class SolveIVP(AbstractIntegrator):
    """Adaptive ``scipy.integrate.solve_ivp`` with terminal contact events (reference, slow).

    Parameters
    ----------
    method : str, default "DOP853"
        A ``solve_ivp`` method (``"RK23"``, ``"RK45"``, ``"DOP853"``, ``"Radau"``, ``"BDF"``,
        ``"LSODA"``).
    rtol, atol : float
        Tolerances passed to ``solve_ivp`` (> 0); ``atol`` is absolute in the dimensionless
        state (lengths / ``L_ref``).
    max_step : float or None
        Largest step (dimensionless time). ``None``: 1/16 of the period of the fastest linear
        motion (drive or highest mode), so that a short contact cannot hide inside one step
        (events are detected by a sign change between step ends).

    Notes
    -----
    ``_advance`` only receives packed arrays, and the force must come from the models' NumPy
    references, so :meth:`run` keeps the systems on the instance for the duration of the call
    (an instance is therefore not re-entrant; create one per thread). ``substeps`` is ignored:
    the step is adaptive.
    """

    def __init__(
        self,
        *,
        method: str = "DOP853",
        rtol: float = 1e-10,
        atol: float = 1e-12,
        max_step: float | None = None,
    ) -> None:
        if method not in _METHODS:
            raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
        self.method = method
        self.rtol = _positive("rtol", rtol)
        self.atol = _positive("atol", atol)
        self.max_step = None if max_step is None else _positive("max_step", max_step)
        self._systems: System | Sequence[System] | None = None

    def run(self, systems: System | Sequence[System], state: State, **options: Any) -> Segment:
        """As :meth:`AbstractIntegrator.run` (same arguments, validation and result)."""
        self._systems = systems
        try:
            return super().run(systems, state, **options)
        finally:
            self._systems = None

    # ------------------------------------------------------------------ the hook
    def _advance(self, state: State, arrays: dict[str, np.ndarray], omega: np.ndarray,
                 gap_rate: np.ndarray, dt: float, n_samples: int, substeps: int,
                 out: dict[str, np.ndarray], record_velocity: bool) -> None:
        if self._systems is None:
            raise RuntimeError("SolveIVP: call run(), not _advance()")
        b = state.batch
        systems = ([self._systems] * b if isinstance(self._systems, System)
                   else list(self._systems))
        for i in range(b):
            self._advance_one(i, systems[i], state, arrays, float(omega[i]),
                              float(gap_rate[i]), dt, n_samples, out, record_velocity)

    def _advance_one(self, b: int, system: System, state: State, arrays: dict[str, np.ndarray],
                     om: float, gr: float, dt: float, n_samples: int,
                     out: dict[str, np.ndarray], record_velocity: bool) -> None:
        m = state.q.shape[1]
        force = system.force
        K, d_air, d_con = arrays["K"][b], arrays["Dair"][b], arrays["Dcon"][b]
        S, dc, ds, yb = arrays["S"][b], arrays["dc"][b], arrays["ds"][b], float(arrays["ybase"][b])
        t0, th0, g0 = float(state.tau[b]), float(state.theta[b]), float(state.gap[b])
        has_contact = force.has_contact
        a0, brk = force.a0, force.break_indentation

        def kinematics(t: float, y: np.ndarray) -> tuple[float, float, float, float]:
            th = th0 + om * (t - t0)
            c, s = math.cos(th), math.sin(th)
            z = g0 + gr * (t - t0) - float(np.sum(y[:m])) - yb * s
            zd = gr - float(np.sum(y[m:2 * m])) - yb * om * c
            return z, zd, c, s

        def ts_force(z: float, zd: float, contact: int) -> float:
            return float(force(z, zd, bool(contact)))

        def rhs(t: float, y: np.ndarray, contact: int) -> np.ndarray:
            q, v = y[:m], y[m:2 * m]
            z, zd, c, s = kinematics(t, y)
            f = ts_force(z, zd, contact)
            drive = dc * c + ds * s
            damp = d_con if contact else d_air
            dy = np.empty_like(y)
            dy[:m] = v
            dy[m:2 * m] = drive - damp * v - K * q - S * f
            dy[2 * m] = drive @ v
            dy[2 * m + 1] = damp @ (v * v)
            dy[2 * m + 2] = f * (S @ v)
            dy[2 * m + 3] = -f * zd
            dy[2 * m + 4] = 1.0 if contact else 0.0
            return dy

        def event(contact: int) -> Callable[[float, np.ndarray], float]:
            z_switch = a0 if not contact else a0 - brk

            def g(t: float, y: np.ndarray, *_: Any) -> float:
                return kinematics(t, y)[0] - z_switch

            g.terminal = True  # type: ignore[attr-defined]
            g.direction = -1.0 if not contact else 1.0  # type: ignore[attr-defined]
            return g

        max_step = self.max_step
        if max_step is None:
            fastest = max(om, float(np.sqrt(K[-1])))
            max_step = 2.0 * math.pi / (16.0 * fastest)

        y = np.concatenate([state.q[b], state.v[b], np.zeros(N_WORK)])
        contact = int(state.contact[b])
        if has_contact:  # a regime inconsistent with the start gap switches at once (as RK4)
            z_start = kinematics(t0, y)[0]
            if (z_start < a0 - EVENT_TOL) if not contact else (z_start > a0 - brk + EVENT_TOL):
                contact = 1 - contact
        t = t0
        t_end = t0 + n_samples * dt
        times = t0 + dt * np.arange(n_samples)
        k = 0  # next sample to record
        n_events = 0
        while True:
            sol = solve_ivp(rhs, (t, t_end), y, method=self.method, rtol=self.rtol,
                            atol=self.atol, max_step=max_step, dense_output=True,
                            events=[event(contact)] if has_contact else None, args=(contact,))
            if sol.status == -1:
                raise FloatingPointError(f"solve_ivp failed at tau = {sol.t[-1]}: {sol.message}")
            t_stop = float(sol.t[-1])
            last = n_samples if sol.status == 0 else int(np.searchsorted(times, t_stop, "left"))
            if last > k:
                ys = sol.sol(times[k:last])
                out["q"][b, :, k:last] = ys[:m]
                if record_velocity:
                    out["v"][b, :, k:last] = ys[m:2 * m]
                for j in range(k, last):
                    z, zd, _, _ = kinematics(float(times[j]), ys[:, j - k])
                    out["force"][b, j] = ts_force(z, zd, contact)
                out["contact"][b, k:last] = contact
                k = last
            y = sol.y[:, -1].copy()
            t = t_stop
            if sol.status == 0:
                break
            contact = 1 - contact
            n_events += 1
            if n_events > _MAX_EVENTS_PER_SAMPLE * n_samples + 16:
                raise FloatingPointError(f"regime chattering at tau = {t}: too many events")
        state.q[b] = y[:m]
        state.v[b] = y[m:2 * m]
        state.work[b] += y[2 * m:]
        state.contact[b] = contact
        state.tau[b] = t_end
        state.theta[b] = (th0 + om * (t_end - t0)) % (2.0 * math.pi)
        state.gap[b] = g0 + gr * (t_end - t0)

    def __repr__(self) -> str:
        return (f"SolveIVP(method={self.method!r}, rtol={self.rtol!r}, atol={self.atol!r}, "
                f"max_step={self.max_step!r})")
