"""A lean, hand-written ``solve_ivp`` baseline for the VdW--DMT models (benchmarks only).

This is what a careful user would write without the simulator: a right-hand side in plain
Python floats (no NumPy call per evaluation for the force), the same modal equations as
``simulator/integrate/_kernel.py::_rhs``

    q_i'' + D_i(regime) q_i' + K_i q_i = dc_i cos(theta) + ds_i sin(theta) - s_i F(z, regime)
    z = g - sum_i q_i - y sin(theta),   theta = theta0 + Omega (tau - tau0)

with terminal events ``z = a0`` that switch the regime and restart the integration, and the
samples read from ``t_eval``. It is the favourable solve_ivp timing; the project's reference
``simulator.integrate.scipy_ref.SolveIVP`` (force from the model's NumPy ``__call__``, work
integrals, force recording) is slower per step and is timed separately.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from simulator import State, System


def lean_solve_ivp(system: System, state: State, *, omega: float, n_samples: int, dt: float,
                   method: str = "DOP853", rtol: float = 1e-8, atol: float = 1e-10,
                   max_step: float | None = None, b: int = 0) -> tuple[np.ndarray, State]:
    """Integrate trajectory ``b`` of ``state``; return ``(q (M, n_samples), end state)``.

    Samples at ``tau0 + k dt``, k = 0 .. n_samples - 1, like ``AbstractIntegrator.run``; the
    end state is at ``tau0 + n_samples dt``. ``max_step`` defaults to 1/16 of the period of
    the fastest linear motion (as ``SolveIVP``), so a contact cannot hide inside one step.
    """
    cl, f, ex = system.cantilever, system.force, system.excitation
    m = cl.n_modes
    K = [float(v) for v in cl.stiffness]
    Da = [float(v) for v in cl.damping]
    Dc = [float(v) for v in cl.contact_damping]
    S = [float(v) for v in cl.force_gain]
    cc, cs = ex.modal_drive(cl, omega)
    cc = [float(v) for v in cc]
    cs = [float(v) for v in cs]
    yb = float(ex.gap_modulation)
    a0, vdw, G, p = f.a0, f.vdw, f.stiffness, f.exponent
    fad = vdw / a0**2
    t0 = float(state.tau[b])
    th0 = float(state.theta[b])
    g0 = float(state.gap[b])
    rng = range(m)

    def rhs(t, y, contact):
        th = th0 + omega * (t - t0)
        c = math.cos(th)
        s = math.sin(th)
        x = 0.0
        for i in rng:
            x += y[i]
        z = g0 - x - yb * s
        if contact:
            d = a0 - z
            force = G * math.copysign(abs(d) ** p, d) - fad
            D = Dc
        else:
            force = -vdw / (z * z)
            D = Da
        out = [0.0] * (2 * m)
        for i in rng:
            out[i] = y[m + i]
            out[m + i] = cc[i] * c + cs[i] * s - D[i] * y[m + i] - K[i] * y[i] - S[i] * force
        return out

    def gap_event(contact):
        def ev(t, y, *_):
            x = 0.0
            for i in rng:
                x += y[i]
            return g0 - x - yb * math.sin(th0 + omega * (t - t0)) - a0
        ev.terminal = True
        ev.direction = 1.0 if contact else -1.0
        return ev

    if max_step is None:
        max_step = 2.0 * math.pi / (16.0 * max(omega, math.sqrt(K[-1])))
    times = t0 + dt * np.arange(n_samples)
    t_end = t0 + n_samples * dt
    q = np.empty((m, n_samples))
    y = np.concatenate([state.q[b], state.v[b]])
    contact = int(state.contact[b])
    t = t0
    k = 0
    while True:
        te = np.append(times[k:], t_end)  # the last entry gives the end state
        sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol,
                        max_step=max_step, t_eval=te, events=[gap_event(contact)],
                        args=(contact,))
        if sol.status == -1:
            raise FloatingPointError(sol.message)
        if sol.status == 0:
            q[:, k:] = sol.y[:m, :-1]
            y = sol.y[:, -1]
            break
        nk = sol.t.size
        q[:, k:k + nk] = sol.y[:m]
        k += nk
        t = float(sol.t_events[0][0])
        y = np.asarray(sol.y_events[0][0], dtype=float)
        contact = 1 - contact
    end = State(y[None, :m].copy(), y[None, m:].copy(), np.int8(contact), t_end,
                (th0 + omega * (t_end - t0)) % (2 * math.pi), g0)
    return q, end
