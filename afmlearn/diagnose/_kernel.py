"""Compiled fixed-step RK4 of a diagnosis model (one or two modes, neck state, detector).

    q1'' + D q1' + K q1 = B cos(Omega tau - phi) - F
    q2'' + D2 q2' + K2 q2 = g2 (B cos(Omega tau - phi) - F)          (if two modes)
    x = q1 + q2,  z = gap - x,  y = x + b2 x^2 + b3 x^3

``F = sum_j c_j theta_j(z, z') + attached * n0 (z - a0) / d_c`` for ``a0 < z``, where
``attached`` switches on at ``z <= a0`` and off at ``z > a0 + d_c`` (checked once per step).
Checked against :func:`simulate_reference` (plain Python) in the tests.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from afmlearn.identify.library._kernel import force_value

__all__ = ["simulate_model", "simulate_reference"]



@nb.njit(cache=True)
def _force(z: float, zd: float, attached: bool, kinds: np.ndarray, p1: np.ndarray,
           p2: np.ndarray, coefs: np.ndarray, a0: float, neck: np.ndarray, dc: float) -> float:
    f = force_value(kinds, p1, p2, coefs, a0, z, zd, 0.0)
    if attached and z > a0 and dc > 0.0:
        f += neck[0] * (z - a0) / dc
    return f


@nb.njit(cache=True)
def _accel(s: np.ndarray, tau: float, attached: bool, lever: np.ndarray, kinds: np.ndarray,
           p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray, a0: float, neck: np.ndarray,
           dc: float, out: np.ndarray) -> None:
    # lever = [gap, K, D, B, phi, omega, K2, D2, g2, two_modes]
    x = s[0] + s[2]
    v = s[1] + s[3]
    f = _force(lever[0] - x, -v, attached, kinds, p1, p2, coefs, a0, neck, dc)
    d = lever[3] * math.cos(lever[5] * tau - lever[4])
    out[0] = s[1]
    out[1] = d - f - lever[2] * s[1] - lever[1] * s[0]
    if lever[9] > 0.5:
        out[2] = s[3]
        out[3] = lever[8] * (d - f) - lever[7] * s[3] - lever[6] * s[2]
    else:
        out[2] = 0.0
        out[3] = 0.0


@nb.njit(cache=True)
def _rk4_step(s: np.ndarray, tau: float, h: float, att: bool, lever: np.ndarray,
              kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray, a0: float,
              neck: np.ndarray, dc: float, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray,
              k4: np.ndarray, tmp: np.ndarray, out: np.ndarray) -> None:
    """One classical RK4 step of length ``h`` from ``s`` into ``out`` (neck state frozen)."""
    _accel(s, tau, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k1)
    for j in range(4):
        tmp[j] = s[j] + 0.5 * h * k1[j]
    _accel(tmp, tau + 0.5 * h, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k2)
    for j in range(4):
        tmp[j] = s[j] + 0.5 * h * k2[j]
    _accel(tmp, tau + 0.5 * h, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k3)
    for j in range(4):
        tmp[j] = s[j] + h * k3[j]
    _accel(tmp, tau + h, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k4)
    for j in range(4):
        out[j] = s[j] + h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@nb.njit(cache=True)
def _crossing(s: np.ndarray, t: float, left: float, att: bool, thr: float, lever: np.ndarray,
              kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray, a0: float,
              neck: np.ndarray, dc: float, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray,
              k4: np.ndarray, tmp: np.ndarray, new: np.ndarray, f_end: float) -> float:
    """Step length in (0, left] at which ``z - thr`` changes sign (Illinois regula falsi).

    The RK4 step from ``s`` is a smooth function of its length, so the located time, and
    with it the state after the switch, depends smoothly on ``s``: the one-period map stays
    differentiable, as Newton shooting needs.
    """
    gap = lever[0]
    a, fa = 0.0, gap - s[0] - s[2] - thr
    b, fb = left, f_end
    side = 0
    for _ in range(60):
        c = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
        if not (a < c < b):
            c = 0.5 * (a + b)
        _rk4_step(s, t, c, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k1, k2, k3, k4,
                  tmp, new)
        fc = gap - new[0] - new[2] - thr
        if fc * fb > 0.0:
            b, fb = c, fc
            if side == -1:
                fa *= 0.5
            side = -1
        else:
            a, fa = c, fc
            if side == 1:
                fb *= 0.5
            side = 1
        if abs(b - a) < 1e-14 * max(left, 1e-300) or fc == 0.0:
            break
    if fb == 0.0 or fb == fa:
        return b
    c = (a * fb - b * fa) / (fb - fa)
    return c if 0.0 < c <= left else b


@nb.njit(cache=True)
def _advance(s: np.ndarray, tau: float, h: float, att: bool, lever: np.ndarray,
             kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray, a0: float,
             neck: np.ndarray, dc: float, k1: np.ndarray, k2: np.ndarray, k3: np.ndarray,
             k4: np.ndarray, tmp: np.ndarray, new: np.ndarray) -> bool:
    """Advance ``s`` in place by ``h``, stopping at every switch of the force.

    Switches: contact onset ``z = a0`` (either way; attaches the neck on the way in) and, while
    the neck holds, its snap at ``z = a0 + d_c`` on the way out. A step that crosses one is cut
    at the crossing (located to round-off, see ``_crossing``), the neck flag is set from the
    crossing's direction, and the rest of the step follows. Locating the switch removes the
    first-order error a fixed step makes at a jump or kink of the force, which resonance
    amplifies about Q times in the orbit. Returns the new neck flag.
    """
    gap = lever[0]
    left = h
    t = tau
    # the regime is carried, not re-read from z: right after a located switch round-off may
    # put z on either side of it
    contact = gap - s[0] - s[2] <= a0
    for _event in range(8):
        _rk4_step(s, t, left, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k1, k2, k3,
                  k4, tmp, new)
        z1 = gap - new[0] - new[2]
        best = left + 1.0
        kind = -1
        if contact != (z1 <= a0):
            best = _crossing(s, t, left, att, a0, lever, kinds, p1, p2, coefs, a0, neck, dc,
                             k1, k2, k3, k4, tmp, new, z1 - a0)
            kind = 0
        if att and not contact and dc > 0.0 and z1 > a0 + dc:
            tb = _crossing(s, t, left, att, a0 + dc, lever, kinds, p1, p2, coefs, a0, neck, dc,
                           k1, k2, k3, k4, tmp, new, z1 - a0 - dc)
            if tb < best:
                best, kind = tb, 1
        if kind < 0:
            for j in range(4):
                s[j] = new[j]
            break
        _rk4_step(s, t, best, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k1, k2, k3, k4,
                  tmp, new)
        for j in range(4):
            s[j] = new[j]
        if kind == 0:
            contact = not contact
            if contact:
                att = True      # contact forms: the neck attaches
        else:
            att = False         # the neck snaps
        t += best
        left -= best
        if left <= 1e-15 * h:
            break
    return att


@nb.njit(cache=True)
def simulate_model(state0: np.ndarray, attached0: bool, tau0: float, dtau: float,
                   n_samples: int, substeps: int, lever: np.ndarray, kinds: np.ndarray,
                   p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray, a0: float,
                   neck: np.ndarray, dc: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """Total deflection ``x`` and rate at ``tau0 + i dtau``, shape (2, n_samples); NaN on blow-up.

    ``state0 = [q1, q1', q2, q2']``. Also returns the state and neck flag after the last
    sample's step (to continue a run). Switches of the force (contact onset ``z = a0``, neck
    snap ``z = a0 + d_c``) are located within each step (see ``_advance``).
    """
    out = np.empty((2, n_samples))
    s = state0.copy()
    new = np.empty(4)
    k1 = np.empty(4)
    k2 = np.empty(4)
    k3 = np.empty(4)
    k4 = np.empty(4)
    tmp = np.empty(4)
    h = dtau / substeps
    tau = tau0
    att = attached0
    for i in range(n_samples):
        out[0, i] = s[0] + s[2]
        out[1, i] = s[1] + s[3]
        for _ in range(substeps):
            att = _advance(s, tau, h, att, lever, kinds, p1, p2, coefs, a0, neck, dc, k1, k2,
                           k3, k4, tmp, new)
            tau += h
        if not (abs(s[0]) < 1e6 and abs(s[2]) < 1e6):
            out[:, i:] = np.nan
            s[:] = np.nan
            break
    return out, s, att


def simulate_reference(state0, attached0, tau0, dtau, n_samples, substeps, lever, force):
    """Plain-Python twin of :func:`simulate_model`; ``force(z, zd, attached)`` gives ``F``."""
    gap, K, D, B, phi, omega, K2, D2, g2, two = (float(v) for v in lever)
    a0 = force.a0
    dc = force.dc

    def acc(s, tau, att):
        x, v = s[0] + s[2], s[1] + s[3]
        f = force(gap - x, -v, att)
        d = B * math.cos(omega * tau - phi)
        a = [s[1], d - f - D * s[1] - K * s[0], 0.0, 0.0]
        if two > 0.5:
            a[2], a[3] = s[3], g2 * (d - f) - D2 * s[3] - K2 * s[2]
        return np.array(a)

    s = np.array(state0, float)
    att = bool(attached0)
    h = dtau / substeps
    tau = tau0
    out = np.empty((2, n_samples))

    def step(s, tau, h, att):
        a1 = acc(s, tau, att)
        a2 = acc(s + 0.5 * h * a1, tau + 0.5 * h, att)
        a3 = acc(s + 0.5 * h * a2, tau + 0.5 * h, att)
        a4 = acc(s + h * a3, tau + h, att)
        return s + h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)

    def cross(s, t, left, att, thr):
        from scipy.optimize import brentq
        return brentq(lambda c: gap - (m := step(s, t, c, att))[0] - m[2] - thr, 0.0, left,
                      xtol=1e-15, rtol=1e-15)

    for i in range(n_samples):
        out[:, i] = s[0] + s[2], s[1] + s[3]
        for _ in range(substeps):
            left, t = h, tau
            contact = gap - s[0] - s[2] <= a0
            for _event in range(8):
                new = step(s, t, left, att)
                z1 = gap - new[0] - new[2]
                best, kind = left + 1.0, -1
                if contact != (z1 <= a0):
                    best, kind = cross(s, t, left, att, a0), 0
                if att and not contact and dc > 0 and z1 > a0 + dc:
                    tb = cross(s, t, left, att, a0 + dc)
                    if tb < best:
                        best, kind = tb, 1
                if kind < 0:
                    s = new
                    break
                s = step(s, t, best, att)
                if kind == 0:
                    contact = not contact
                    att = att or contact
                else:
                    att = False
                t += best
                left -= best
                if left <= 1e-15 * h:
                    break
            tau += h
    return out
