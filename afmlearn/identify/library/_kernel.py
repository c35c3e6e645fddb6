"""Compiled evaluation of an identified force ``sum_j c_j theta_j(z, z', x; a0)``.

The library's ``(kind, p1, p2)`` encoding (:mod:`.base` ``Kind``) is the simulator's one
force-law representation (:mod:`simulator.forces.law`), evaluated by its one compiled
evaluator with contact read from the gap (``z <= a0``). Tested against every term's NumPy
``evaluate``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from simulator.forces._kernel import law_force
from simulator.forces._kernel import term_value as _term_value

__all__ = ["force_series", "force_value", "term_value"]


@nb.njit(cache=True)
def term_value(kind: int, p1: float, p2: float, a0: float, z: float, zd: float,
               x: float) -> float:
    """Value of one term (kernel twin of ``AbstractTerm.evaluate``)."""
    contact = z <= a0
    return _term_value(kind, p1, p2, a0, z, zd, x, contact, contact)


@nb.njit(cache=True)
def force_value(kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
                a0: float, z: float, zd: float, x: float) -> float:
    """``F_ts = sum_j coefs[j] * theta_j`` at one state."""
    contact = z <= a0
    return law_force(kinds, p1, p2, coefs, a0, z, zd, x, contact, contact)


@nb.njit(cache=True)
def force_series(kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
                 a0: float, z: np.ndarray, zd: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``F_ts`` along a trajectory, shape (n,)."""
    out = np.empty(z.shape[0])
    for i in range(z.shape[0]):
        out[i] = force_value(kinds, p1, p2, coefs, a0, z[i], zd[i], x[i])
    return out
