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
           "invert_polynomial", "bvls"]

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
def _small_lstsq(M: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Least-squares solution of ``M z = rhs`` (``M`` shape (p, k), p >= k, a few columns):
    Householder QR and back substitution; LAPACK ``gelsd`` (minimum norm) where ``M`` is
    numerically rank-deficient (a diagonal of R below 1e-12 of the largest)."""
    p, k = M.shape
    A = M.copy()
    y = rhs.copy()
    for j in range(k):
        nx = 0.0
        for i in range(j, p):
            nx += A[i, j] * A[i, j]
        nx = math.sqrt(nx)
        if nx == 0.0:
            continue
        alpha = -nx if A[j, j] >= 0.0 else nx
        v = A[j:, j].copy()
        v[0] -= alpha
        vv = 0.0
        for i in range(v.size):
            vv += v[i] * v[i]
        if vv == 0.0:
            continue
        for col in range(j, k):
            d = 0.0
            for i in range(v.size):
                d += v[i] * A[j + i, col]
            f = 2.0 * d / vv
            for i in range(v.size):
                A[j + i, col] -= f * v[i]
        d = 0.0
        for i in range(v.size):
            d += v[i] * y[j + i]
        f = 2.0 * d / vv
        for i in range(v.size):
            y[j + i] -= f * v[i]
    dmax = 0.0
    for j in range(k):
        dmax = max(dmax, abs(A[j, j]))
    for j in range(k):
        if not abs(A[j, j]) > 1e-12 * dmax:
            return np.linalg.lstsq(M, rhs, -1.0)[0]
    z = np.empty(k)
    for j in range(k - 1, -1, -1):
        acc = y[j]
        for i in range(j + 1, k):
            acc -= A[j, i] * z[i]
        z[j] = acc / A[j, j]
    return z


@nb.njit(cache=True)
def _free_lstsq(R: np.ndarray, rhs: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Least-squares solution of ``R[:, free] z = rhs``, shape (n_free,)."""
    idx = np.flatnonzero(free)
    Rf = np.empty((R.shape[0], idx.size))
    for j in range(idx.size):
        Rf[:, j] = R[:, idx[j]]
    return _small_lstsq(Rf, rhs)


@nb.njit(cache=True)
def bvls(R: np.ndarray, c: np.ndarray, const: float, lb: np.ndarray, ub: np.ndarray,
         tol: float = 1e-10) -> np.ndarray:
    """Bounded-variable least squares ``min |R x - c|^2`` s.t. ``lb <= x <= ub`` (shapes
    (p, p), (p,), (p,), (p,)): the algorithm of Stark & Parker (1995) as SciPy's
    ``lsq_linear(method="bvls")`` runs it (its initialisation from the clipped unconstrained
    solution, its KKT and cost-change stops at ``tol``), on a problem already reduced by QR:
    ``A = Q R``, ``c = Q^T b``, ``const = |b|^2 - |c|^2`` (the part of the cost no ``x``
    changes, kept so that the relative cost-change stop is SciPy's). A coefficient that reaches
    a bound is put on it exactly (SciPy's interpolation can leave it one rounding outside).
    Returns ``x``, shape (p,)."""
    n = R.shape[1]
    x = _small_lstsq(R, c)
    inside = True
    for i in range(n):
        if not (lb[i] <= x[i] <= ub[i]):
            inside = False
    if inside:
        return x
    on_bound = np.zeros(n)
    for i in range(n):
        if x[i] <= lb[i]:
            x[i] = lb[i]
            on_bound[i] = -1.0
        elif x[i] >= ub[i]:
            x[i] = ub[i]
            on_bound[i] = 1.0
    r = R @ x - c
    cost = 0.5 * (r @ r + const)
    # initialisation: the free variables' solution, violators moved to their bounds, until
    # the free solution is feasible
    free = on_bound == 0.0
    iteration = 0
    while free.any():
        iteration += 1
        fixed = np.where(free, 0.0, x)
        z = _free_lstsq(R, c - R @ fixed, free)
        idx = np.flatnonzero(free)
        any_v = False
        for k in range(idx.size):
            i = idx[k]
            if z[k] < lb[i]:
                x[i] = lb[i]
                on_bound[i] = -1.0
                any_v = True
            elif z[k] > ub[i]:
                x[i] = ub[i]
                on_bound[i] = 1.0
                any_v = True
            else:
                x[i] = z[k]
        if not any_v:
            break
        free = on_bound == 0.0
    r = R @ x - c
    cost = 0.5 * (r @ r + const)
    g = R.T @ r
    max_iter = n + iteration
    for _ in range(iteration, max_iter):
        opt = 0.0
        for i in range(n):
            v = abs(g[i]) if on_bound[i] == 0.0 else g[i] * on_bound[i]
            opt = max(opt, v)
        if opt < tol:
            break
        best, move = -np.inf, 0
        for i in range(n):
            if g[i] * on_bound[i] > best:
                best, move = g[i] * on_bound[i], i
        on_bound[move] = 0.0
        while True:
            free = on_bound == 0.0
            idx = np.flatnonzero(free)
            fixed = np.where(free, 0.0, x)
            z = _free_lstsq(R, c - R @ fixed, free)
            alpha, hit, side = np.inf, -1, 0.0
            for k in range(idx.size):
                i = idx[k]
                if z[k] < lb[i]:
                    a = (lb[i] - x[i]) / (z[k] - x[i])
                    if a < alpha:
                        alpha, hit, side = a, i, -1.0
            for k in range(idx.size):
                i = idx[k]
                if z[k] > ub[i]:
                    a = (ub[i] - x[i]) / (z[k] - x[i])
                    if a < alpha:
                        alpha, hit, side = a, i, 1.0
            if hit < 0:
                for k in range(idx.size):
                    x[idx[k]] = z[k]
                break
            for k in range(idx.size):
                i = idx[k]
                x[i] = x[i] * (1.0 - alpha) + alpha * z[k]
            on_bound[hit] = side
            x[hit] = lb[hit] if side < 0.0 else ub[hit]     # on it, not a rounding beside it
        r = R @ x - c
        cost_new = 0.5 * (r @ r + const)
        if cost - cost_new < tol * cost:
            break
        cost = cost_new
        g = R.T @ r
    return x


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
