"""Compiled evaluation of an identified force ``sum_j c_j theta_j(z, z', x; a0)``.

Mirrors the NumPy ``evaluate`` of every term (:mod:`.base` ``Kind`` codes); tested against it.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .base import Kind

_CONSTANT = Kind.CONSTANT
_DEFLECTION_POWER = Kind.DEFLECTION_POWER
_INVERSE_POWER = Kind.INVERSE_POWER
_CONTACT = Kind.CONTACT
_INDENTATION = Kind.INDENTATION
_INDENTATION_RATE = Kind.INDENTATION_RATE
_GAP_RATE = Kind.GAP_RATE
_EXPONENTIAL_DAMPING = Kind.EXPONENTIAL_DAMPING
_SPHERE_ELECTROSTATIC = Kind.SPHERE_ELECTROSTATIC


@nb.njit(cache=True, fastmath=False)
def term_value(kind: int, p1: float, p2: float, a0: float, z: float, zd: float,
               x: float) -> float:
    """Value of one term (kernel twin of ``AbstractTerm.evaluate``)."""
    contact = z <= a0
    if kind == _CONSTANT:
        return 1.0
    if kind == _DEFLECTION_POWER:
        return x ** int(p1)
    if kind == _INVERSE_POWER:
        return a0 ** (-p1) if contact else z ** (-p1)
    if kind == _CONTACT:
        return 1.0 if contact else 0.0
    if kind == _INDENTATION:
        return (a0 - z) ** p1 if contact else 0.0
    if kind == _INDENTATION_RATE:
        if not contact:
            return 0.0
        rate = -zd
        r = rate if p2 == 1.0 else rate * rate
        return (a0 - z) ** p1 * r
    if kind == _GAP_RATE:
        if contact:
            return 0.0
        r = zd if p2 == 1.0 else zd * zd
        return z ** p1 * r
    if kind == _EXPONENTIAL_DAMPING:
        return math.exp(-z / p1) * zd
    if kind == _SPHERE_ELECTROSTATIC:
        zz = a0 if contact else z
        return 1.0 / (zz * (zz + p1))
    return math.nan


@nb.njit(cache=True)
def force_value(kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
                a0: float, z: float, zd: float, x: float) -> float:
    """``F_ts = sum_j coefs[j] * theta_j`` at one state."""
    f = 0.0
    for j in range(kinds.shape[0]):
        if coefs[j] != 0.0:
            f += coefs[j] * term_value(kinds[j], p1[j], p2[j], a0, z, zd, x)
    return f


@nb.njit(cache=True)
def force_series(kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
                 a0: float, z: np.ndarray, zd: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``F_ts`` along a trajectory, shape (n,)."""
    out = np.empty(z.shape[0])
    for i in range(z.shape[0]):
        out[i] = force_value(kinds, p1, p2, coefs, a0, z[i], zd[i], x[i])
    return out
