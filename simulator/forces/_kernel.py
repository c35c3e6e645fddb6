"""Compiled evaluation of a :class:`~simulator.forces.law.ForceLaw` (the one force evaluator).

Used by the integrator kernel (``simulator/integrate/_kernel.py``), by the identifier's library
(``afmlearn.identify.library._kernel``) and through them by the diagnosis. Every term family of
``law.Kind`` is evaluated in :func:`term_value`; each force model and library term is tested
against its NumPy reference.

Powers of the indentation are extended oddly (``sign(d) |d|**p``) so that the integrator's
Runge--Kutta stages may step a little past the switching surface without producing NaN.

numba's on-disk cache keys a function on its own file only: after editing this file, delete
the ``*.nbi``/``*.nbc`` files of ``simulator/integrate``, ``afmlearn/identify`` and
``afmlearn/diagnose`` (their kernels embed this code), or they keep running the old version.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .law import Kind

_CONSTANT = Kind.CONSTANT
_DEFLECTION_POWER = Kind.DEFLECTION_POWER
_INVERSE_POWER = Kind.INVERSE_POWER
_CONTACT = Kind.CONTACT
_INDENTATION = Kind.INDENTATION
_INDENTATION_RATE = Kind.INDENTATION_RATE
_GAP_RATE = Kind.GAP_RATE
_EXPONENTIAL_DAMPING = Kind.EXPONENTIAL_DAMPING
_SPHERE_ELECTROSTATIC = Kind.SPHERE_ELECTROSTATIC
_SPHERE_VDW = Kind.SPHERE_VDW
_JKR_CUBE = Kind.JKR_CUBE
_JKR_THREE_HALVES = Kind.JKR_THREE_HALVES
_DETACHED_POWER = Kind.DETACHED_POWER
_NECK = Kind.NECK


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


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def inverse_pow(z: float, n: float) -> float:
    """``z**-n`` with fast paths for n = 1, 2, 8."""
    if n == 2.0:
        return 1.0 / (z * z)
    if n == 8.0:
        z2 = z * z
        z4 = z2 * z2
        return 1.0 / (z4 * z4)
    if n == 1.0:
        return 1.0 / z
    return z ** (-n)


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
def term_value(kind: int, p1: float, p2: float, a0: float, z: float, zd: float, x: float,
               contact: bool, attached: bool) -> float:
    """Value ``theta`` of one term (module table of :mod:`simulator.forces.law`).

    Parameters
    ----------
    kind : int
        ``law.Kind`` code.
    p1, p2 : float
        Shape parameters of the term.
    a0 : float
        Contact onset (dimensionless).
    z, zd, x : float
        Gap, gap rate ``dz/dtau`` and deflection (dimensionless).
    contact, attached : bool
        Regime flags.

    Out of contact the distance terms read ``max(z, a0)``: the integrator's trial RK4 stages
    can pass a contact switch it has not located yet, and there the free-side force must be
    the continuous extension from the switch, not ``z**-n`` near ``z = 0`` (which threw the
    tip through the sample: rows at 10--1e11 free amplitudes in spectroscopy series).
    """
    if kind == _INVERSE_POWER:
        return inverse_pow(a0 if contact or z < a0 else z, p1)
    if kind == _INDENTATION:
        return signed_pow(a0 - z, p1) if contact else 0.0
    if kind == _INDENTATION_RATE:
        if not contact:
            return 0.0
        rate = -zd
        r = rate if p2 == 1.0 else rate * rate
        return signed_pow(a0 - z, p1) * r
    if kind == _EXPONENTIAL_DAMPING:
        return math.exp(-z / p1) * zd
    if kind == _SPHERE_ELECTROSTATIC:
        zz = a0 if contact or z < a0 else z
        return 1.0 / (zz * (zz + p1))
    if kind == _SPHERE_VDW:
        zz = a0 if contact or z < a0 else z
        w = zz * (zz + 2.0 * p1)
        return 1.0 / (w * w)
    if kind == _CONTACT:
        return 1.0 if contact else 0.0
    if kind == _CONSTANT:
        return 1.0
    if kind == _DEFLECTION_POWER:
        return x ** int(p1)
    if kind == _GAP_RATE:
        if contact:
            return 0.0
        r = zd if p2 == 1.0 else zd * zd
        return max(z, a0) ** p1 * r
    if kind == _JKR_CUBE:
        if not attached:
            return 0.0
        s = jkr_contact_radius_sqrt(a0 - z, p1, p2)
        s3 = s * s * s
        return s3 * s3
    if kind == _JKR_THREE_HALVES:
        if not attached:
            return 0.0
        s = jkr_contact_radius_sqrt(a0 - z, p1, p2)
        return s * s * s
    if kind == _DETACHED_POWER:
        return 0.0 if attached else inverse_pow(max(z, a0), p1)
    if kind == _NECK:
        return (z - a0) / p1 if (attached and not contact and p1 > 0.0) else 0.0
    return math.nan


@njit(cache=True, inline="always", _nrt=False)
def law_force(kinds, p1, p2, coefs, a0: float, z: float, zd: float, x: float, contact: bool,
              attached: bool) -> float:
    """``F = sum_j coefs[j] theta_j`` at one state (terms with a zero coefficient skipped).

    The two families of the common contact laws (``INVERSE_POWER``, ``INDENTATION``) are
    evaluated here, the others through :func:`term_value`. Kept small and inlined: in the
    integrator a larger body here (e.g. the JKR radius solve) measured 2--3x slower steps.

    Parameters
    ----------
    kinds : int64 array, shape (n_terms,)
    p1, p2, coefs : float64 arrays, shape (n_terms,)
        A law's encoding (``ForceLaw.arrays``).
    a0, z, zd, x, contact, attached :
        As in :func:`term_value`.

    Returns
    -------
    float
        Force in units of ``k L_ref``, positive = repulsive.
    """
    f = 0.0
    for j in range(kinds.shape[0]):
        c = coefs[j]
        if c == 0.0:
            continue
        k = kinds[j]
        if k == _INVERSE_POWER:
            f += c * inverse_pow(a0 if contact or z < a0 else z, p1[j])
        elif k == _INDENTATION:
            if contact:
                f += c * signed_pow(a0 - z, p1[j])
        else:
            f += c * term_value(k, p1[j], p2[j], a0, z, zd, x, contact, attached)
    return f


@njit(cache=True)
def law_series(kinds, p1, p2, coefs, a0: float, z, zd, x, contact, attached):
    """``F`` along a trajectory: arrays ``z, zd, x`` (n,), flags ``contact, attached`` (n,)."""
    out = np.empty(z.shape[0])
    for i in range(z.shape[0]):
        out[i] = law_force(kinds, p1, p2, coefs, a0, z[i], zd[i], x[i], contact[i],
                           attached[i])
    return out
