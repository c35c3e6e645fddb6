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
=====  =========================================================================
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

N_LAW = 10

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
