"""The diagnosis model on the one compiled integrator (one or two modes, neck, detector).

    q1'' + D q1' + K q1 = B cos(Omega tau - phi) - F
    q2'' + D2 q2' + K2 q2 = g2 (B cos(Omega tau - phi) - F)          (if two modes)
    x = q1 + q2,  z = gap - x,  y = x + b2 x^2 + b3 x^3

``F = sum_j c_j theta_j(z, z', attached)``: the library's terms and, with a neck, the JKR neck's
terms (:class:`~afmlearn.diagnose.spec.AbstractNeck`), gated on ``attached``, which switches on
at ``z <= a0`` and off at ``z > a0 + d_c``. The model is a :class:`simulator.forces.ForceLaw`
integrated by :func:`simulator.integrate._kernel.integrate_one` with located switches, library
terms gated on ``z <= a0`` at every stage (``geometric``) and no graded steps (the one-period
map stays smooth, as Newton shooting needs). Checked against :func:`simulate_reference` (plain
Python) in the tests.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from simulator.forces._kernel import jkr_contact_radius_sqrt
from simulator.integrate._kernel import CONTACT, FREE, N_WORK, NECK, integrate_one

__all__ = ["simulate_model", "simulate_reference", "jkr_radius_sqrt", "neck_state",
           "invert_polynomial"]

#: a run whose modal deflection exceeds this (units of L_ref) has blown up
BLOWUP = 1e6


@nb.njit(cache=True)
def jkr_radius_sqrt(delta: np.ndarray, r_j: float, c_j: float) -> np.ndarray:
    """``s = sqrt(a)`` of the JKR contact radius at each indentation ``delta`` (shape (n,)):
    the simulator's own solve (:func:`simulator.forces._kernel.jkr_contact_radius_sqrt`,
    stable branch, held at the neck limit ``s_m`` below ``delta_c``) over an array."""
    out = np.empty(delta.shape[0])
    for i in range(delta.shape[0]):
        out[i] = jkr_contact_radius_sqrt(delta[i], r_j, c_j)
    return out


@nb.njit(cache=True)
def neck_state(z: np.ndarray, a0: float, neck_length: float) -> np.ndarray:
    """Attached (neck) state along one period of a periodic orbit of gaps ``z`` (shape (n,)).

    The tip attaches when ``z <= a0`` and detaches when ``z > a0 + neck_length``; the period is
    swept twice so that the state at its start is the one the orbit itself leaves there.
    """
    n = z.shape[0]
    out = np.zeros(n, np.bool_)
    on = False
    for sweep in range(2):
        for i in range(n):
            if z[i] <= a0:
                on = True
            elif z[i] > a0 + neck_length:
                on = False
            if sweep == 1:
                out[i] = on
    return out


@nb.njit(cache=True)
def invert_polynomial(y: np.ndarray, b: np.ndarray) -> np.ndarray:
    """True deflection ``x`` with ``y = x + b[0] x^2 + b[1] x^3 + ..`` at every sample of ``y``
    (shape (n,)): Newton from ``x = y``, the slope held at ``|d| >= 0.2`` (the map's inverse
    branch through 0), at most 30 steps, each sample until its step is below 1e-13."""
    out = np.empty(y.shape[0])
    for i in range(y.shape[0]):
        x = y[i]
        for _ in range(30):
            g = x - y[i]
            d = 1.0
            xk = x                       # x^(k-1), k = 2, 3, ..
            for j in range(b.shape[0]):
                g += b[j] * xk * x
                d += (j + 2.0) * b[j] * xk
                xk *= x
            if abs(d) < 0.2:
                d = 0.2 if d >= 0.0 else -0.2
            step = g / d
            x -= step
            if abs(step) < 1e-13:
                break
        out[i] = x
    return out


@nb.njit(cache=True)
def simulate_model(state0: np.ndarray, attached0: bool, tau0: float, dtau: float,
                   n_samples: int, substeps: int, lever: np.ndarray, kinds: np.ndarray,
                   p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray, a0: float,
                   dc: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """Total deflection ``x`` and rate at ``tau0 + i dtau``, shape (2, n_samples); NaN on blow-up.

    ``state0 = [q1, q1', q2, q2']``; ``lever = [gap, K, D, B, phi, Omega, K2, D2, g2,
    two_modes]``; ``kinds, p1, p2, coefs`` the force law's terms (library terms, then the
    neck's), ``dc`` the neck's break distance past ``a0`` (0: no neck). Also returns the state
    and neck flag after the last sample's step (to continue a run). Switches of the force
    (contact onset ``z = a0``, neck snap ``z = a0 + d_c``) are located within each step. With
    one mode, ``q2`` (an offset of the gap) and ``q2'`` are carried unchanged.
    """
    two = lever[9] > 0.5
    m = 2 if two else 1
    with_neck = dc > 0.0
    hdr = np.array([a0, 1.0, dc if with_neck else 0.0, 1.0])
    B = lever[3]
    K = np.array([lever[1], lever[6]])[:m]
    D = np.array([lever[2], lever[7]])[:m]
    S = np.array([1.0, lever[8]])[:m]
    drive = np.array([B, lever[8] * B])[:m]
    q = np.array([state0[0], state0[2]])[:m]
    v = np.array([state0[1], state0[3]])[:m]
    off_x = 0.0 if two else state0[2]
    off_v = 0.0 if two else state0[3]
    gap = lever[0] - off_x
    z0 = gap - np.sum(q)
    r = CONTACT if z0 <= a0 else (NECK if (attached0 and with_neck) else FREE)
    q_out = np.empty((m, n_samples))
    v_out = np.empty((m, n_samples))
    f_out = np.empty(n_samples)
    c_out = np.empty(n_samples, np.int8)
    r = integrate_one(q, v, np.zeros(N_WORK), r, lever[5] * tau0 - lever[4], lever[5], drive,
                      np.zeros(m), 0.0, gap, 0.0, K, D, D, S, kinds, p1, p2, coefs, hdr,
                      dtau, n_samples, substeps, True, True, False,
                      BLOWUP, q_out, v_out, f_out, c_out, True)
    out = np.empty((2, n_samples))
    for i in range(n_samples):
        out[0, i] = off_x
        out[1, i] = off_v
        for j in range(m):
            out[0, i] += q_out[j, i]
            out[1, i] += v_out[j, i]
    s = np.empty(4)
    s[0] = q[0]
    s[1] = v[0]
    s[2] = q[1] if two else state0[2]
    s[3] = v[1] if two else state0[3]
    if not (np.isfinite(q[0]) and np.isfinite(s[2])):
        s[:] = np.nan
    return out, s, r != FREE


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
