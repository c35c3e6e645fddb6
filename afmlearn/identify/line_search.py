"""One-dimensional search used by the identifier's profiles: a grid, then a bounded refinement.

The contact onset ``a0`` and the exponent's inner ``a0`` search have rough, multi-modal costs
(a support switches as ``a0`` moves), so a local method alone lands in the nearest valley. The
grid finds the valley; :func:`scipy.optimize.minimize_scalar` (bounded, Brent) refines between
the best grid point's neighbours. Every ``a0`` search of :mod:`.single`, :mod:`.joint` and
:mod:`.fixed_exponent` goes through :func:`grid_then_bounded`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

__all__ = ["grid_then_bounded"]

FloatArray = NDArray[np.float64]


def grid_then_bounded(cost: Callable[[float], float], grid: FloatArray, *, maxiter: int,
                      xatol: float | None = None) -> tuple[float, float, FloatArray]:
    """Minimise ``cost`` on ``grid``, then between the best point's neighbours.

    Parameters
    ----------
    cost : callable
        Scalar cost of one abscissa (same units as ``grid``); NaN or inf marks a failed point.
    grid : ndarray, shape (n,)
        Increasing abscissae (e.g. ``a0`` in units of L_ref), ``n >= 1``.
    maxiter : int
        Iterations of the bounded refinement (>= 1).
    xatol : float, optional
        Absolute abscissa tolerance of the refinement (scipy's default when None).

    Returns
    -------
    x : float
        The best abscissa: the refined one if it is better than the best grid point.
    value : float
        ``cost(x)``.
    values : ndarray, shape (n,)
        The cost at every grid point (the profile).

    Notes
    -----
    No refinement when the best grid point is an end point (the minimum may lie outside the
    grid: the caller's range decides) or when no grid point has a finite cost.
    """
    grid = np.asarray(grid, dtype=float)
    assert grid.ndim == 1 and grid.size >= 1 and maxiter >= 1
    values = np.array([cost(float(a)) for a in grid], dtype=float)
    finite = np.isfinite(values)
    i = int(np.argmin(np.where(finite, values, np.inf))) if finite.any() else 0
    best_x, best = float(grid[i]), float(values[i])
    if 0 < i < grid.size - 1 and math.isfinite(best):
        options: dict[str, float] = {"maxiter": maxiter}
        if xatol is not None:
            options["xatol"] = xatol
        res = minimize_scalar(cost, bounds=(float(grid[i - 1]), float(grid[i + 1])),
                              method="bounded", options=options)
        if res.fun < best:
            best_x, best = float(res.x), float(res.fun)
    return best_x, best, values
