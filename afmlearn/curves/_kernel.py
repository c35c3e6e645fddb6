"""Compiled slow flow (Krylov--Bogoliubov averaging) of a single-mode lever along a ramp.

Single mode, force excitation (``physics.md`` §2): ``x'' + x'/Q + x = -F_ts(z, z') + B cos(W tau)``
with ``z = d - x`` and the ansatz ``x = A cos(theta)``, ``theta = W tau - phi`` (``phi`` = lag).
Averaging over one period gives (``<.> = (1/2 pi) int_0^{2 pi} . d theta``)::

    A'   = -A / (2Q) + B sin(phi) / (2W) + <F sin theta> / W
    phi' = (W**2 - 1) / (2W) + B cos(phi) / (2 A W) - <F cos theta> / (A W)

with ``z = d - A cos theta`` and ``z' = A W sin theta`` (retracting on ``0 < theta < pi``).
The averages are split at the regime switches (contact at ``z = a0``; the adhesion neck, held
on the retracting half until ``z = a0 + d_neck``) and each smooth piece is integrated by
Gauss--Legendre quadrature, so the kinks of the contact law cost no accuracy.

Law vector (dimensionless, lengths / ``L_ref``, forces / ``k L_ref``), ``F > 0`` repulsive:

=====  =========================================================================
index  term
=====  =========================================================================
0      ``a0`` contact onset
1      ``vdw``: ``-vdw / z**2`` out of contact, ``-vdw / a0**2`` in contact and neck
2      ``stiffness`` ``E``: ``+E delta**p`` in contact (``delta = a0 - z``)
3      ``p`` contact exponent
4      ``visco``: ``+c_v delta**0.5 delta'`` in contact (``delta' = -z'``)
5      ``damping``: ``-c_e exp(-z / z_b) z'`` at all gaps
6      ``z_b`` decay length
7      ``electrostatic``: ``-c_es / (z (z + R))`` at all gaps (held at ``a0`` in contact)
8      ``R`` electrostatic radius
9      ``neck``: on the retracting half, a contact made at the bottom breaks at
       ``z = a0 + neck``; in between the force is held at ``-vdw / a0**2``
10     ``far_damping``: ``-c_f exp(-z / z_f) z'`` at all gaps (a second damping term, for a
       loss far from the sample, e.g. squeeze-film damping over microns, next to a
       near-contact one)
11     ``z_f`` its decay length
=====  =========================================================================
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

N_LAW = 12

_GL_X, _GL_W = np.polynomial.legendre.leggauss(12)


@njit(cache=True, error_model="numpy")
def force(law, z: float, zd: float, mode: int) -> float:
    """Force at gap ``z``, rate ``zd``; ``mode`` 0 free, 1 contact, 2 neck (attached)."""
    a0 = law[0]
    f = 0.0
    if mode == 1:
        d = a0 - z
        f += -law[1] / (a0 * a0) + law[2] * math.copysign(abs(d) ** law[3], d)
        if law[4] != 0.0:
            f += law[4] * math.sqrt(abs(d)) * (-zd)
        zl = a0
    elif mode == 2:
        f -= law[1] / (a0 * a0)
        zl = z
    else:
        f -= law[1] / (z * z)
        zl = z
    if law[5] != 0.0:
        f -= law[5] * math.exp(-z / law[6]) * zd
    if law[10] != 0.0:
        f -= law[10] * math.exp(-z / law[11]) * zd
    if law[7] != 0.0:
        f -= law[7] / (zl * (zl + law[8]))
    return f


@njit(cache=True, error_model="numpy")
def _piece(law, d, amp, omega, ta, tb, mode, gx, gw):
    """``(int F sin, int F cos)`` over ``theta`` in ``[ta, tb]``."""
    s = 0.0
    c = 0.0
    if tb <= ta:
        return s, c
    h = 0.5 * (tb - ta)
    m = 0.5 * (tb + ta)
    for j in range(gx.shape[0]):
        th = m + h * gx[j]
        st = math.sin(th)
        ct = math.cos(th)
        f = force(law, d - amp * ct, amp * omega * st, mode)
        s += gw[j] * f * st
        c += gw[j] * f * ct
    return s * h, c * h


@njit(cache=True, error_model="numpy")
def averages(law, d: float, amp: float, omega: float, gx, gw):
    """``(<F sin theta>, <F cos theta>)`` over one cycle at rest gap ``d``, amplitude ``amp``."""
    a0 = law[0]
    pi = math.pi
    if amp <= 0.0:
        return 0.0, 0.0
    # theta where z = a0 (contact) and z = a0 + neck (break), on [0, pi]
    u1 = (d - a0) / amp
    th1 = 0.0 if u1 >= 1.0 else (pi if u1 <= -1.0 else math.acos(u1))
    touched = u1 < 1.0
    th2 = th1
    if touched and law[9] > 0.0:
        u2 = (d - a0 - law[9]) / amp
        th2 = 0.0 if u2 >= 1.0 else (pi if u2 <= -1.0 else math.acos(u2))
    s = 0.0
    c = 0.0
    # retracting half: contact [0, th1], neck [th1, th2], free [th2, pi]
    ps, pc = _piece(law, d, amp, omega, 0.0, th1, 1, gx, gw)
    s += ps
    c += pc
    ps, pc = _piece(law, d, amp, omega, th1, th2, 2, gx, gw)
    s += ps
    c += pc
    ps, pc = _piece(law, d, amp, omega, th2, pi, 0, gx, gw)
    s += ps
    c += pc
    # approaching half: free [pi, 2 pi - th1], contact [2 pi - th1, 2 pi]
    ps, pc = _piece(law, d, amp, omega, pi, 2.0 * pi - th1, 0, gx, gw)
    s += ps
    c += pc
    ps, pc = _piece(law, d, amp, omega, 2.0 * pi - th1, 2.0 * pi, 1, gx, gw)
    s += ps
    c += pc
    return s / (2.0 * pi), c / (2.0 * pi)


@njit(cache=True, error_model="numpy")
def rates(law, d, amp, phi, q, omega, drive, gx, gw):
    """``(A', phi')`` of the averaged equations (module docstring)."""
    fs, fc = averages(law, d, amp, omega, gx, gw)
    a = max(amp, 1e-9)
    da = -a / (2.0 * q) + drive * math.sin(phi) / (2.0 * omega) + fs / omega
    dphi = ((omega * omega - 1.0) / (2.0 * omega) + drive * math.cos(phi) / (2.0 * a * omega)
            - fc / (a * omega))
    return da, dphi


@njit(cache=True, error_model="numpy")
def integrate(law, gap, h, amp0, phi0, q, omega, drive, gx, gw, max_turn):
    """RK4 on the grid ``tau_k = k h`` with rest gap ``gap[k]`` (linear in between).

    Each interval is split into as many equal sub-steps as keep the phase turn and the relative
    amplitude change per sub-step below ``max_turn``.

    Returns
    -------
    amp, phi : ndarray, shape (n,)
        Amplitude and lag at the grid points (``amp[0] = amp0``).
    """
    n = gap.shape[0]
    amp = np.empty(n)
    phi = np.empty(n)
    amp[0] = amp0
    phi[0] = phi0
    a = amp0
    p = phi0
    for k in range(n - 1):
        d0 = gap[k]
        d1 = gap[k + 1]
        ka, kp = rates(law, d0, a, p, q, omega, drive, gx, gw)
        r = max(abs(kp), abs(ka) / max(a, 1e-6))
        m = min(max(int(math.ceil(h * r / max_turn)), 1), 256)
        hs = h / m
        for j in range(m):
            da = d0 + (d1 - d0) * j / m
            dm = d0 + (d1 - d0) * (j + 0.5) / m
            db = d0 + (d1 - d0) * (j + 1.0) / m
            if j > 0:
                ka, kp = rates(law, da, a, p, q, omega, drive, gx, gw)
            k2a, k2p = rates(law, dm, a + 0.5 * hs * ka, p + 0.5 * hs * kp, q, omega, drive,
                             gx, gw)
            k3a, k3p = rates(law, dm, a + 0.5 * hs * k2a, p + 0.5 * hs * k2p, q, omega, drive,
                             gx, gw)
            k4a, k4p = rates(law, db, a + hs * k3a, p + hs * k3p, q, omega, drive, gx, gw)
            a += hs * (ka + 2.0 * k2a + 2.0 * k3a + k4a) / 6.0
            p += hs * (kp + 2.0 * k2p + 2.0 * k3p + k4p) / 6.0
            a = max(a, 1e-9)
        amp[k + 1] = a
        phi[k + 1] = p
    return amp, phi


@njit(cache=True, error_model="numpy")
def _gap_at(gap, h, t):
    """Rest gap at time ``t`` from the grid ``gap[k]`` at ``k h`` (linear, held at the ends)."""
    x = t / h
    n = gap.shape[0]
    if x <= 0.0:
        return gap[0]
    k = int(x)
    if k >= n - 1:
        return gap[n - 1]
    f = x - k
    return gap[k] + (gap[k + 1] - gap[k]) * f


# Dormand--Prince 5(4) tableau (Hairer, Norsett, Wanner, Solving ODEs I, table 5.2)
_C2, _C3, _C4, _C5 = 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0
_A21 = 1.0 / 5.0
_A31, _A32 = 3.0 / 40.0, 9.0 / 40.0
_A41, _A42, _A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
_A51, _A52, _A53, _A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
_A61, _A62, _A63, _A64, _A65 = (9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0,
                                -5103.0 / 18656.0)
_B1, _B3, _B4, _B5, _B6 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, \
    11.0 / 84.0
# error weights: 5th-order minus embedded 4th-order weights
_E1, _E3, _E4, _E5, _E6, _E7 = (71.0 / 57600.0, -71.0 / 16695.0, 71.0 / 1920.0,
                                -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0)
# 4th-order continuous extension (Hairer's DOPRI5, ``contd5``)
_D1, _D3, _D4, _D5, _D6, _D7 = (-12715105075.0 / 11282082432.0, 87487479700.0 / 32700410799.0,
                                -10690763975.0 / 1880347072.0,
                                701980252875.0 / 199316789632.0,
                                -1453857185.0 / 822651844.0, 69997945.0 / 29380423.0)


@njit(cache=True, error_model="numpy")
def _dense(y0, y1, k1, k7, r5, hs, s):
    """DOPRI5 dense output at fraction ``s`` of a step of length ``hs``."""
    dy = y1 - y0
    b = hs * k1 - dy
    return y0 + s * (dy + (1.0 - s) * (b + s * (dy - hs * k7 - b + (1.0 - s) * r5)))


@njit(cache=True, error_model="numpy")
def integrate_adaptive(law, gap, h, amp0, phi0, q, omega, drive, gx, gw, tol, max_step,
                       min_step):
    """The slow flow of :func:`integrate` with Dormand--Prince 5(4) steps of controlled error.

    The rest gap is the grid ``gap[k]`` at ``tau_k = k h``, linear in between; the steps are
    free of the grid: long where the flow is smooth (the far field, steady parts), short at the
    branch jumps, each keeping the local error estimate below ``tol`` (absolute, on the
    amplitude / free amplitude and the lag [rad]). The states at the grid points come from
    the method's 4th-order continuous extension (Hairer, Norsett, Wanner, DOPRI5).

    Parameters
    ----------
    tol : float
        Local error per step (> 0).
    max_step : float
        Longest step (dimensionless time, > 0).
    min_step : float
        Shortest step: a step this short is accepted whatever its error estimate. The averaged
        rates jump where the adhesion neck switches on (``d - A = a0``); a state sliding along
        that switch would otherwise be chased with ever shorter steps (measured: 5e6 steps,
        100 s, for one curve). There the result is a fixed-step solution of that step, as the
        RK4 reference's 256 sub-steps are.

    Returns
    -------
    amp, phi : ndarray, shape (n,)
        Amplitude and lag at the grid points (``amp[0] = amp0``).
    nsteps : int
        Accepted plus rejected steps (each costs six rate evaluations).
    """
    n = gap.shape[0]
    amp = np.empty(n)
    phi = np.empty(n)
    amp[0] = amp0
    phi[0] = phi0
    t_end = (n - 1) * h
    t = 0.0
    a = amp0
    p = phi0
    ka, kp = rates(law, gap[0], a, p, q, omega, drive, gx, gw)
    step = min(h, max_step)
    nxt = 1
    nsteps = 0
    while nxt < n:
        hs = min(step, t_end - t)
        if hs <= 1e-12 * h:
            hs = t_end - t
        nsteps += 1
        k2a, k2p = rates(law, _gap_at(gap, h, t + _C2 * hs), a + hs * _A21 * ka,
                         p + hs * _A21 * kp, q, omega, drive, gx, gw)
        k3a, k3p = rates(law, _gap_at(gap, h, t + _C3 * hs),
                         a + hs * (_A31 * ka + _A32 * k2a),
                         p + hs * (_A31 * kp + _A32 * k2p), q, omega, drive, gx, gw)
        k4a, k4p = rates(law, _gap_at(gap, h, t + _C4 * hs),
                         a + hs * (_A41 * ka + _A42 * k2a + _A43 * k3a),
                         p + hs * (_A41 * kp + _A42 * k2p + _A43 * k3p), q, omega, drive,
                         gx, gw)
        k5a, k5p = rates(law, _gap_at(gap, h, t + _C5 * hs),
                         a + hs * (_A51 * ka + _A52 * k2a + _A53 * k3a + _A54 * k4a),
                         p + hs * (_A51 * kp + _A52 * k2p + _A53 * k3p + _A54 * k4p),
                         q, omega, drive, gx, gw)
        k6a, k6p = rates(law, _gap_at(gap, h, t + hs),
                         a + hs * (_A61 * ka + _A62 * k2a + _A63 * k3a + _A64 * k4a
                                   + _A65 * k5a),
                         p + hs * (_A61 * kp + _A62 * k2p + _A63 * k3p + _A64 * k4p
                                   + _A65 * k5p), q, omega, drive, gx, gw)
        an = a + hs * (_B1 * ka + _B3 * k3a + _B4 * k4a + _B5 * k5a + _B6 * k6a)
        pn = p + hs * (_B1 * kp + _B3 * k3p + _B4 * k4p + _B5 * k5p + _B6 * k6p)
        an = max(an, 1e-9)
        k7a, k7p = rates(law, _gap_at(gap, h, t + hs), an, pn, q, omega, drive, gx, gw)
        ea = hs * (_E1 * ka + _E3 * k3a + _E4 * k4a + _E5 * k5a + _E6 * k6a + _E7 * k7a)
        ep = hs * (_E1 * kp + _E3 * k3p + _E4 * k4p + _E5 * k5p + _E6 * k6p + _E7 * k7p)
        err = max(abs(ea), abs(ep)) / tol
        if not math.isfinite(err):
            err = 1e10
        if err <= 1.0 or hs <= min_step:
            t1 = t + hs
            # grid points in (t, t1]: the continuous extension of the step
            r5a = hs * (_D1 * ka + _D3 * k3a + _D4 * k4a + _D5 * k5a + _D6 * k6a + _D7 * k7a)
            r5p = hs * (_D1 * kp + _D3 * k3p + _D4 * k4p + _D5 * k5p + _D6 * k6p + _D7 * k7p)
            while nxt < n and nxt * h <= t1 * (1.0 + 1e-14):
                s = (nxt * h - t) / hs
                amp[nxt] = _dense(a, an, ka, k7a, r5a, hs, s)
                phi[nxt] = _dense(p, pn, kp, k7p, r5p, hs, s)
                nxt += 1
            t = t1
            a, p, ka, kp = an, pn, k7a, k7p
            fac = 5.0 if err < 1e-10 else min(5.0, 0.9 * err ** -0.2)
        else:
            fac = max(0.2, 0.9 * err ** -0.2)
        step = max(min(hs * fac, max_step), min_step)
    return amp, phi, nsteps
