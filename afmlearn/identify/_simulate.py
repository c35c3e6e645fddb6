"""An identified single-mode model on the one compiled integrator (for state accuracy).

    x'' = -D x' - K x + B cos(Omega tau - phi) - F_ts(z, z', x),   z = gap - x,  z' = -x'

``F_ts`` is the library's terms (a :class:`simulator.forces.ForceLaw` encoding) with contact
read from ``z <= a0`` at every stage; the run is plain fixed-step RK4 of
:func:`simulator.integrate._kernel.integrate_one` without located switches (``locate=False``):
the force's kink or jump at ``z = a0`` gives first-order local errors there, so the step is a
fraction (``substeps``) of the sampling interval. Checked against scipy's ``solve_ivp`` in the
tests.

:func:`simulate_period` is the output-error stage's one-period map
(:mod:`afmlearn.identify.output_error`): the same kernel WITH the switches at ``a0`` located,
so the end state is a smooth function of the state and the parameters (Newton shooting and
finite-difference Jacobians need that).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from simulator.integrate._kernel import FREE, N_WORK, integrate_one

#: a run whose deflection exceeds this (units of L_ref) has blown up
BLOWUP = 1e6


@nb.njit(cache=True)
def simulate_rk4(x0: float, v0: float, tau0: float, dtau: float, n_samples: int, substeps: int,
                 gap: float, K: float, D: float, B: float, phi: float, omega: float,
                 kinds: np.ndarray, p1: np.ndarray, p2: np.ndarray, coefs: np.ndarray,
                 a0: float) -> tuple[np.ndarray, np.ndarray]:
    """Deflection and velocity at ``tau0 + i dtau``, each shape (n_samples,); NaN on blow-up."""
    q = np.array([x0])
    v = np.array([v0])
    q_out = np.empty((1, n_samples))
    v_out = np.empty((1, n_samples))
    f_out = np.empty(n_samples)
    c_out = np.empty(n_samples, np.int8)
    hdr = np.array([a0, 1.0, 0.0, 1.0])
    d = np.array([D])
    integrate_one(q, v, np.zeros(N_WORK), FREE, omega * tau0 - phi, omega, np.array([B]),
                  np.zeros(1), 0.0, gap, 0.0, np.array([K]), d, d, np.ones(1), kinds, p1, p2,
                  coefs, hdr, dtau, n_samples, substeps, False, True, False, BLOWUP, q_out,
                  v_out, f_out, c_out, True)
    return q_out[0], v_out[0]


@nb.njit(cache=True)
def simulate_period(x0: float, v0: float, n_out: int, substeps: int, gap: float, K: float,
                    D: float, B: float, omega: float, kinds: np.ndarray, p1: np.ndarray,
                    p2: np.ndarray, coefs: np.ndarray, a0: float
                    ) -> tuple[np.ndarray, float, float]:
    """One drive period of the phase-0 model (drive ``B cos(Omega tau)``) from ``(x0, v0)`` at
    ``tau = 0``, with the contact switches at ``z = a0`` located (the state after a switch is
    a smooth function of the parameters, as shooting and finite-difference Jacobians need).

    Returns the deflection at ``tau = k T / n_out``, k = 0 .. n_out - 1 (shape (n_out,),
    units of L_ref) and the state ``(x, x')`` at ``tau = T = 2 pi / Omega``; NaN on blow-up.
    """
    q = np.array([x0])
    v = np.array([v0])
    q_out = np.empty((1, n_out))
    v_out = np.empty((1, 0))
    f_out = np.empty(n_out)
    c_out = np.empty(n_out, np.int8)
    hdr = np.array([a0, 1.0, 0.0, 1.0])
    d = np.array([D])
    integrate_one(q, v, np.zeros(N_WORK), FREE, 0.0, omega, np.array([B]), np.zeros(1), 0.0,
                  gap, 0.0, np.array([K]), d, d, np.ones(1), kinds, p1, p2, coefs, hdr,
                  2.0 * np.pi / omega / n_out, n_out, substeps, True, True, False, BLOWUP,
                  q_out, v_out, f_out, c_out, False)
    return q_out[0], q[0], v[0]
