"""Base class of the Gram-matrix optimizers and the constrained least-squares solver they share.

Every optimizer here solves a linear regression ``y ~ Theta xi`` through the normal equations
only: ``G = Theta^T Theta``, ``b = Theta^T y`` and ``yy = y^T y`` carry everything the fit needs.
This is what makes model selection cheap (a fold's Gram is a sum of block Grams, so a fit costs
O(p^3) instead of O(n p^2)) and it keeps the optimizers usable inside ``pysindy.SINDy``: the
pysindy entry point ``fit(x, y)`` forms the Gram matrices and hands them to ``fit_gram``.
"""

from __future__ import annotations

import abc

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pysindy.optimizers import BaseOptimizer
from scipy.optimize import linprog
from sklearn.utils.validation import check_X_y

__all__ = ["GramOptimizer", "InfeasibleError", "constrained_lstsq", "gram_statistics"]


class InfeasibleError(ValueError):
    """The equality constraints cannot be met within the bounds (on the given support)."""


def gram_statistics(theta: ArrayLike, y: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    """Normal-equation statistics of a regression problem.

    Parameters
    ----------
    theta : array-like, shape (n_rows, n_features)
        Library matrix.
    y : array-like, shape (n_rows,) or (n_rows, n_targets)
        Targets.

    Returns
    -------
    G : ndarray, shape (n_features, n_features)
        ``theta^T theta``.
    b : ndarray, shape (n_features, n_targets)
        ``theta^T y``.
    yy : ndarray, shape (n_targets,)
        ``sum(y**2)`` per target.
    """
    theta = np.asarray(theta, dtype=float)
    y2 = np.asarray(y, dtype=float)
    if y2.ndim == 1:
        y2 = y2[:, None]
    return theta.T @ theta, theta.T @ y2, np.einsum("ij,ij->j", y2, y2)


def constrained_lstsq(
    H: ArrayLike,
    g: ArrayLike,
    *,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    A: ArrayLike | None = None,
    d: ArrayLike | None = None,
    x0: ArrayLike | None = None,
    max_iter: int | None = None,
) -> NDArray:
    """Minimise ``1/2 x^T H x - g^T x`` subject to ``lower <= x <= upper`` and ``A x = d``.

    A primal active-set method (Nocedal & Wright, Algorithm 16.3) for the small convex QP of a
    least-squares refit (``H = Theta_S^T Theta_S`` positive semidefinite, a few dozen variables).
    Equalities are always in the working set; bounds enter and leave it. The start point is
    ``clip(x0)`` (default: the clipped unconstrained minimiser) when it satisfies ``A x = d``,
    otherwise a feasible vertex from ``scipy.optimize.linprog`` (HiGHS). Every iterate is
    feasible, so the result is feasible even if ``max_iter`` stops a (degenerate) cycle.

    Parameters
    ----------
    H : array-like, shape (n, n)
        Symmetric positive semidefinite matrix.
    g : array-like, shape (n,)
        Linear term.
    lower, upper : array-like, shape (n,), optional
        Bounds (``-inf`` / ``+inf`` for none; default unbounded).
    A : array-like, shape (m, n), optional
        Equality constraint matrix.
    d : array-like, shape (m,), optional
        Equality right-hand side.
    x0 : array-like, shape (n,), optional
        Start guess (clipped to the bounds).
    max_iter : int, optional
        Iteration cap (default ``10 * (n + m) + 50``).

    Returns
    -------
    x : ndarray, shape (n,)

    Raises
    ------
    InfeasibleError
        If no ``x`` within the bounds satisfies ``A x = d``.
    """
    H = np.asarray(H, dtype=float)
    g = np.asarray(g, dtype=float)
    n = g.size
    lo = np.full(n, -np.inf) if lower is None else np.asarray(lower, dtype=float).copy()
    hi = np.full(n, np.inf) if upper is None else np.asarray(upper, dtype=float).copy()
    if A is None or np.size(A) == 0:
        A = np.zeros((0, n))
        d = np.zeros(0)
    A = np.asarray(A, dtype=float).reshape(-1, n)
    d = np.asarray(d, dtype=float).ravel()
    m = A.shape[0]
    if n == 0:
        if m and np.any(np.abs(d) > 1e-12 * (1 + np.abs(d))):
            raise InfeasibleError("equality constraints need a coefficient outside the support")
        return np.zeros(0)
    if max_iter is None:
        max_iter = 10 * (n + m) + 50
    scale = max(1.0, float(np.max(np.abs(np.diag(H)))))

    if x0 is None:
        x0 = np.linalg.lstsq(H, g, rcond=None)[0]
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    if m and np.max(np.abs(A @ x - d)) > 1e-10 * (1 + np.max(np.abs(d))):
        res = linprog(np.zeros(n), A_eq=A, b_eq=d, bounds=list(zip(lo, hi, strict=True)),
                      method="highs")
        if res.status != 0:
            raise InfeasibleError("no coefficients within the bounds satisfy the equality "
                                  f"constraints ({res.message})")
        x = np.clip(res.x, lo, hi)
    # working set: +1 = at upper bound, -1 = at lower bound, 0 = free
    side = np.zeros(n, dtype=int)
    side[(x <= lo) & np.isfinite(lo)] = -1
    side[(x >= hi) & np.isfinite(hi)] = 1
    side[(lo == hi)] = -1
    need_step = True  # False right after a full step: x is the working set's minimiser
    for _ in range(max_iter):
        grad = H @ x - g
        free = side == 0
        nf = int(free.sum())
        Af = A[:, free]
        if need_step and nf:
            kkt = np.zeros((nf + m, nf + m))
            kkt[:nf, :nf] = H[np.ix_(free, free)]
            kkt[:nf, nf:] = Af.T
            kkt[nf:, :nf] = Af
            sol = np.linalg.lstsq(kkt, np.concatenate([-grad[free], np.zeros(m)]),
                                  rcond=None)[0]
            p = np.zeros(n)
            p[free] = sol[:nf]
            if np.max(np.abs(p)) > 1e-13 * (1.0 + np.max(np.abs(x))):
                alpha, block = 1.0, -1
                for j in np.flatnonzero(free & (p != 0)):
                    bound = hi[j] if p[j] > 0 else lo[j]
                    if np.isfinite(bound):
                        a = (bound - x[j]) / p[j]
                        if a < alpha:
                            alpha, block = max(a, 0.0), j
                x = x + alpha * p
                if block >= 0:
                    side[block] = 1 if p[block] > 0 else -1
                    x[block] = hi[block] if p[block] > 0 else lo[block]
                else:
                    need_step = False
                continue
        # x minimises over the working set: multipliers of the equalities, then of the bounds
        mu = np.linalg.lstsq(Af.T, -grad[free], rcond=None)[0] if (m and nf) else np.zeros(m)
        r = grad + A.T @ mu
        lam = np.where(side == -1, r, np.where(side == 1, -r, np.inf))
        lam[lo == hi] = np.inf  # fixed variables never leave
        j = int(np.argmin(lam))
        if lam[j] >= -1e-10 * scale * (1.0 + np.max(np.abs(x))):
            break
        side[j] = 0
        need_step = True
    return np.clip(x, lo, hi)


class GramOptimizer(BaseOptimizer, abc.ABC):
    """A pysindy optimizer that fits from the normal-equation statistics only.

    Subclasses implement :meth:`fit_gram`; :meth:`fit` (the pysindy / scikit-learn entry point)
    drops rows with a NaN, applies sample weights, forms ``G``, ``b``, ``yy`` and calls the
    pysindy hook :meth:`_reduce`, which calls :meth:`fit_gram`. Column normalisation and the
    unbiasing refit are the subclass's business (they must respect its constraints, which
    pysindy's ``BaseOptimizer.fit`` does not).

    Fitted attributes (pysindy conventions): ``coef_`` shape (n_targets, n_features),
    ``ind_`` (support, bool, same shape), ``intercept_ = 0.0``, ``history_``.
    """

    def set_params(self, **params: object) -> GramOptimizer:
        """scikit-learn ``set_params`` (pysindy 2.1's returns None; this returns ``self``)."""
        super().set_params(**params)
        return self

    def fit(self, x_: ArrayLike, y: ArrayLike, sample_weight: ArrayLike | None = None,
            **reduce_kws: object) -> GramOptimizer:
        """Fit on data rows.

        Parameters
        ----------
        x_ : array-like, shape (n_rows, n_features)
            Library matrix ``Theta`` (rows in time order).
        y : array-like, shape (n_rows,) or (n_rows, n_targets)
            Targets.
        sample_weight : float or array-like, shape (n_rows,), optional
            Row weights (the squared residual of row r is multiplied by ``sample_weight[r]``).

        Returns
        -------
        self
        """
        x = np.asarray(x_, dtype=float)
        yv = np.asarray(y, dtype=float)
        if x.ndim != 2:
            raise ValueError(f"x must be 2-D (n_rows, n_features), got shape {x.shape}")
        y2 = yv.reshape(-1, 1) if yv.ndim == 1 else yv
        if y2.ndim != 2 or y2.shape[0] != x.shape[0]:
            raise ValueError(f"y must have shape ({x.shape[0]},) or ({x.shape[0]}, n_targets),"
                             f" got {yv.shape}")
        good = ~(np.isnan(x).any(axis=1) | np.isnan(y2).any(axis=1))
        x, y2 = x[good], y2[good]
        x, y2 = check_X_y(x, y2, y_numeric=True, multi_output=True, copy=self.copy_X)
        if sample_weight is not None:
            w = np.broadcast_to(np.asarray(sample_weight, dtype=float), good.shape)[good]
            if np.any(w < 0) or not np.all(np.isfinite(w)):
                raise ValueError("sample_weight must be finite and >= 0")
            sw = np.sqrt(w)[:, None]
            x, y2 = x * sw, y2 * sw
        self._reduce(x, y2, **reduce_kws)
        return self

    def _reduce(self, x: NDArray, y: NDArray, **reduce_kws: object) -> None:
        """pysindy hook: fit ``coef_`` (T, p) from rows ``x`` (n, p) and ``y`` (n, T)."""
        G, b, yy = gram_statistics(x, y)
        self.fit_gram(G, b, yy, x.shape[0], **reduce_kws)

    @abc.abstractmethod
    def fit_gram(self, G: ArrayLike, b: ArrayLike, yy: ArrayLike, n_rows: int,
                 **kwargs: object) -> GramOptimizer:
        """Fit from ``G = Theta^T Theta`` (p, p), ``b = Theta^T y`` (p,) or (p, T),
        ``yy = y^T y`` (scalar or (T,)) and the row count; must set ``coef_`` (T, p)."""
