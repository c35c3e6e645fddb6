"""Compiled fixed-step RK4 of an identified single-mode model (for state accuracy).

    x'' = -D x' - K x + B cos(Omega tau - phi) - F_ts(z, z', x),   z = gap - x,  z' = -x'

The force has a kink or jump at ``z = a0``; a fixed step gives first-order local errors at the
switches, so the step is a fraction (``substeps``) of the sampling interval. Checked against
scipy's ``solve_ivp`` in the tests.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .library._kernel import force_value


@nb.njit(cache=True)
def _rhs(x: float, v: float, tau: float, gap: float, K: float, D: float, B: float, phi: float,
         omega: float, kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
         a0: float) -> float:
    f = force_value(kinds, p1, p2, coefs, a0, gap - x, -v, x)
    return -D * v - K * x + B * math.cos(omega * tau - phi) - f


@nb.njit(cache=True)
def simulate_rk4(x0: float, v0: float, tau0: float, dtau: float, n_samples: int, substeps: int,
                 gap: float, K: float, D: float, B: float, phi: float, omega: float,
                 kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
                 a0: float) -> tuple[np.ndarray, np.ndarray]:
    """Deflection and velocity at ``tau0 + i dtau``, each shape (n_samples,); NaN on blow-up."""
    xs = np.empty(n_samples)
    vs = np.empty(n_samples)
    x, v, tau = x0, v0, tau0
    h = dtau / substeps
    for i in range(n_samples):
        xs[i] = x
        vs[i] = v
        for _ in range(substeps):
            k1x = v
            k1v = _rhs(x, v, tau, gap, K, D, B, phi, omega, kinds, p1, p2, coefs, a0)
            k2x = v + 0.5 * h * k1v
            k2v = _rhs(x + 0.5 * h * k1x, k2x, tau + 0.5 * h, gap, K, D, B, phi, omega, kinds,
                       p1, p2, coefs, a0)
            k3x = v + 0.5 * h * k2v
            k3v = _rhs(x + 0.5 * h * k2x, k3x, tau + 0.5 * h, gap, K, D, B, phi, omega, kinds,
                       p1, p2, coefs, a0)
            k4x = v + h * k3v
            k4v = _rhs(x + h * k3x, k4x, tau + h, gap, K, D, B, phi, omega, kinds, p1, p2,
                       coefs, a0)
            x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
            v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
            tau += h
        if not (abs(x) < 1e6):
            xs[i:] = np.nan
            vs[i:] = np.nan
            break
    return xs, vs
