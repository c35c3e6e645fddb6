"""Giessibl's frequency shift of a finite-amplitude oscillation in a conservative force.

For a lever of stiffness ``k`` and free resonance ``f0`` oscillating harmonically with
amplitude ``A`` (zero to peak) whose **lower turning point** (closest approach) is at the gap
``d``, first-order perturbation theory gives (F. J. Giessibl, Phys. Rev. B 56, 16010 (1997))::

    Omega = df / f0 = -(1 / (pi k A)) * integral_{-1}^{1} F(d + A (1 + u)) u / sqrt(1 - u**2) du

with ``F > 0`` repulsive (``physics.md`` section 1). Check of the sign: for ``A -> 0`` this is
``-F'(d) / (2 k)``, so a repulsive force that grows towards the sample (``F' < 0``) stiffens
the spring (``df > 0``). The integral is evaluated by Gauss--Chebyshev quadrature of the first
kind, ``(pi / n) sum_i g(u_i)``, ``u_i = cos((2 i - 1) pi / (2 n))`` (exact for a polynomial
``g`` of degree < 2n; a contact kink converges algebraically, hence the default 128 nodes).
Everything is dimensionless: lengths in ``L_ref``, forces in ``k L_ref``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from simulator.forces._kernel import law_series
from simulator.forces.law import ForceLaw

__all__ = ["chebyshev_nodes", "frequency_shift", "law_force", "law_frequency_shift"]


def chebyshev_nodes(n: int) -> NDArray[np.float64]:
    """Nodes ``u_i = cos((2 i - 1) pi / (2 n))``, shape (n,), of the Gauss--Chebyshev rule."""
    if n < 2:
        raise ValueError(f"n_nodes must be >= 2, got {n}")
    return np.cos((2.0 * np.arange(1, n + 1) - 1.0) * np.pi / (2.0 * n))


def frequency_shift(force: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                    gap: ArrayLike, *, amplitude: float, n_nodes: int = 128
                    ) -> NDArray[np.float64]:
    """Normalised frequency shift ``Omega = df / f0`` at lower turning points ``gap``.

    Parameters
    ----------
    force : callable
        ``F(d)`` [k L_ref] of an array of gaps [L_ref] (any shape), positive = repulsive.
    gap : array_like, shape (n,)
        Lower turning points [L_ref].
    amplitude : float
        Oscillation amplitude [L_ref], > 0.
    n_nodes : int
        Quadrature nodes.

    Returns
    -------
    ndarray, shape (n,)
        ``Omega`` (dimensionless; ``df = Omega f0``).
    """
    if not amplitude > 0.0:
        raise ValueError(f"amplitude must be > 0, got {amplitude!r}")
    d = np.atleast_1d(np.asarray(gap, float))
    u = chebyshev_nodes(n_nodes)
    f = force(d[:, None] + amplitude * (1.0 + u[None, :]))
    return -(f @ u) / (amplitude * n_nodes)


def law_force(law: ForceLaw, gap: ArrayLike) -> NDArray[np.float64]:
    """Conservative force [k L_ref] of a :class:`ForceLaw` at the gaps ``gap`` [L_ref] (any
    shape), in contact where ``gap <= law.a0``; the compiled evaluator of the simulator."""
    z = np.asarray(gap, float)
    flat = np.ascontiguousarray(z.ravel())
    zero = np.zeros_like(flat)
    contact = (flat <= law.a0) if law.has_contact else np.zeros(flat.shape, bool)
    kinds, p1, p2, coefs = law.arrays
    out = law_series(kinds, p1, p2, coefs, float(law.a0), flat, zero, zero, contact, contact)
    return out.reshape(z.shape)


def law_frequency_shift(law: ForceLaw, gap: ArrayLike, *, amplitude: float,
                        n_nodes: int = 128) -> NDArray[np.float64]:
    """:func:`frequency_shift` of a :class:`ForceLaw` (rate terms are zero: ``z' = 0`` is not
    used here, a conservative shift only); shapes as there."""
    if law.dissipative:
        raise ValueError("law: a frequency shift is defined here for conservative laws only")
    return frequency_shift(lambda d: law_force(law, d), gap, amplitude=amplitude,
                           n_nodes=n_nodes)
