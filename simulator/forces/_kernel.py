"""Numba kernel that evaluates the canonical force (see ``_layout``) for one tip.

The contact branch is chosen by the regime flag ``contact`` (a state of the integrator switched
only at located events), not by the sign of ``a0 - z``. Power laws are extended oddly
(``sign(d) |d|**p``) so that the integrator's Runge--Kutta stages may step a little past the
switching surface without producing NaN.
"""

from __future__ import annotations

import math

from numba import njit

from . import _layout as L


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def signed_pow(d: float, p: float) -> float:
    """Odd extension ``sign(d) * |d|**p`` with fast paths for p = 1, 1.5, 2, 0.5."""
    if p == 1.5:
        return d * math.sqrt(abs(d))
    if p == 2.0:
        return d * abs(d)
    if p == 1.0:
        return d
    if p == 0.5:
        return math.copysign(math.sqrt(abs(d)), d)
    return math.copysign(abs(d) ** p, d)


@njit(cache=True, error_model="numpy", _nrt=False)
def jkr_contact_radius_sqrt(delta: float, r_j: float, c_j: float) -> float:
    """Square root ``s = sqrt(a)`` of the JKR contact radius for indentation ``delta``.

    Solves ``s**4 / r_j - c_j s = delta`` on the stable branch ``s >= s_m`` by Newton's method
    from above (the function is convex and increasing there, so the iteration is monotone).
    Below the neck limit ``delta_min`` the radius is held at ``s_m``.
    """
    s_m = (c_j * r_j / 4.0) ** (1.0 / 3.0)
    d_min = -0.75 * c_j * s_m
    if delta <= d_min:
        return s_m
    s = (r_j * abs(delta)) ** 0.25 + (c_j * r_j) ** (1.0 / 3.0)
    for _ in range(60):
        s3 = s * s * s
        g = s3 * s / r_j - c_j * s - delta
        dg = 4.0 * s3 / r_j - c_j
        step = g / dg
        s -= step
        if s < s_m:
            s = s_m
            break
        if abs(step) <= 1e-14 * s:
            break
    return s


@njit(cache=True, error_model="numpy", _nrt=False)
def ts_force(z: float, zdot: float, contact: int, p) -> float:
    """Tip--sample force (dimensionless, > 0 repulsive) at gap ``z`` and gap rate ``zdot``.

    Parameters
    ----------
    z, zdot : float
        Gap and its rate ``dz/dtau`` (dimensionless).
    contact : int
        Regime flag, 1 in contact.
    p : float64 array, shape (N_COEFFICIENTS,)
        Canonical coefficients.
    """
    f = 0.0
    if p[L.LJ_REP] != 0.0:
        z2 = z * z
        z4 = z2 * z2
        f += p[L.LJ_REP] / (z4 * z4)
    if p[L.EXPD] != 0.0:
        f -= p[L.EXPD] * math.exp(-z / p[L.ZB]) * zdot
    # long-range attractions saturate at contact (evaluated at a0 while in contact)
    zl = p[L.A0] if contact != 0 else z
    if p[L.ES] != 0.0:
        f -= p[L.ES] / (zl * (zl + p[L.R_ES]))
    if p[L.SPH] != 0.0:
        w = zl * (zl + 2.0 * p[L.R_SPH])
        f -= p[L.SPH] / (w * w)
    if contact != 0:
        a0 = p[L.A0]
        d = a0 - z
        if p[L.JKR] != 0.0:
            s = jkr_contact_radius_sqrt(d, p[L.JKR_R], p[L.JKR_C])
            s3 = s * s * s
            f += p[L.JKR_ALPHA] * s3 * s3 - p[L.JKR_BETA] * s3
        else:
            f += p[L.E_CONT] * signed_pow(d, p[L.P_CONT]) - p[L.VDW] / (a0 * a0)
        if p[L.VISCO] != 0.0:
            f -= p[L.VISCO] * signed_pow(d, p[L.Q_VISCO]) * zdot
    elif p[L.VDW] != 0.0:
        f -= p[L.VDW] / (z * z)
    return f
