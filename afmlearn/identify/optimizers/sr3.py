"""SR3 with an l0 penalty, box constraints and linear equality constraints (``BoxSR3``).

Objective (physics.md §5; Zheng et al. 2018, Champion et al. 2020), per target ``t``::

    min_{xi, W}  1/2 ||y - Theta xi||^2 + sum_ij lambda_ij [W_ij != 0] + 1/(2 nu) ||xi - W||^2
    s.t.         C vec(xi) = d,        lower <= W <= upper,

with ``lambda_ij = threshold_ij^2 / (2 nu)`` (pysindy's ``SR3.calculate_l0_weight``), so that
without a box the W-step is hard thresholding at ``threshold`` exactly as in pysindy 2.1
(``|xi| > threshold`` is kept). The iteration alternates

- xi-step: ``(G + I/nu) xi = b + W/nu`` subject to ``C vec(xi) = d`` (a KKT solve; the Cholesky
  factor of ``G + I/nu`` and the Schur complement of the constraints are computed once per fit),
- W-step: the exact proximal map of ``lambda [w != 0] + box`` per coordinate: ``w = 0`` (when
  ``0`` is in ``[lower, upper]``) if ``xi^2 <= threshold^2 + (clip(xi) - xi)^2``, else
  ``w = clip(xi, lower, upper)``. A coefficient whose box excludes 0 is never zeroed.

The sparse, box-feasible ``W`` is returned as ``coef_`` (pysindy convention: ``coef_`` is the
regularised variable). With ``unbias=True`` (default) ``W`` is refitted by least squares on its
support subject to the box AND the equality constraints (:func:`constrained_lstsq`), so the result
is sparse, box-feasible and meets ``C vec(coef_) = d``. Without unbiasing ``coef_ = W`` meets the
box exactly and the equalities only up to the thresholding (``coef_full_`` meets them exactly).

Layouts follow pysindy 2.1: ``coef_`` has shape (n_targets, n_features); ``constraint_lhs`` has
one row per constraint and ``n_targets * n_features`` columns, grouped by target
(``constraint_order="target"``: column ``t * n_features + j``) or by feature (``"feature"``:
column ``j * n_targets + t``); the convergence test is pysindy's
``||W_k - W_{k-1}||_F / nu < tol``; ``history_[0]`` is the initial least-squares guess.

Column normalisation: with ``normalize_columns=True`` the iteration runs on
``Theta_n = Theta / ||Theta_j||`` (better conditioned), and the thresholds, boxes and equality
constraints, which are always given in the units of the ORIGINAL coefficients, are mapped into
the normalised coordinates (``threshold_j ||Theta_j||``, ``lower_j ||Theta_j||``,
``C diag(1/||Theta_j||)``). The selected support and the constraints therefore mean the same with
or without normalisation (pysindy applies its constraints to the normalised coefficients). The
relaxation ``nu`` acts on the normalised coefficients.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Literal, final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from sklearn.exceptions import ConvergenceWarning

from afmlearn.identify.optimizers.base import GramOptimizer, InfeasibleError, constrained_lstsq

__all__ = ["BoxSR3"]


@dataclass(frozen=True)
class _Normalised:
    """A fit problem in normalised coordinates (coefficients ``xi_n = xi * norms``)."""

    norms: NDArray  # (p,)
    G: NDArray  # (p, p)
    b: NDArray  # (T, p)
    lower: NDArray  # (T, p)
    upper: NDArray  # (T, p)
    C: NDArray  # (m, T*p), target order
    d: NDArray  # (m,)


class _Factor:
    """Factorisation of the xi-step for one ``nu``: Cholesky of ``G + I/nu`` and the constraint
    Schur complement ``S = C (I_T kron (G + I/nu))^-1 C^T``."""

    def __init__(self, G: NDArray, nu: float, C: NDArray, d: NDArray, n_targets: int) -> None:
        p = G.shape[0]
        self.nu = nu
        self.T = n_targets
        self.C = C
        self.d = d
        try:
            self.chol = cho_factor(G + np.eye(p) / nu)
        except LinAlgError as err:  # G is PSD, so only nu = inf-like values get here
            raise ValueError(f"G + I/nu is not positive definite (nu={nu})") from err
        if C.shape[0]:
            blocks = [cho_solve(self.chol, C[:, t * p:(t + 1) * p].T) for t in range(n_targets)]
            self.M = np.concatenate(blocks, axis=0)  # (T*p, m)
            try:
                self.S = cho_factor(C @ self.M)
            except LinAlgError as err:
                raise ValueError("constraint_lhs must have full row rank (redundant or "
                                 "contradictory equality constraints)") from err

    def solve(self, g: NDArray) -> NDArray:
        """xi-step for a batch: ``g`` (K, T, p) -> constrained minimiser (K, T, p)."""
        K, T, p = g.shape
        x = cho_solve(self.chol, g.reshape(K * T, p).T).T.reshape(K, T * p)
        if self.C.shape[0]:
            mu = cho_solve(self.S, (x @ self.C.T - self.d).T)  # (m, K)
            x = x - (self.M @ mu).T
        return x.reshape(K, T, p)


@final
class BoxSR3(GramOptimizer):
    """SR3 with l0 penalty, per-feature thresholds, box and equality constraints.

    Parameters
    ----------
    threshold : float, default 0.1
        Hard threshold ``eta >= 0`` in the units of the coefficients (``lambda = eta^2/(2 nu)``).
    nu : float, default 1.0
        Relaxation ``nu > 0`` (as pysindy's ``relax_coeff_nu``; it competes with
        ``Theta^T Theta``, which grows with the number of rows).
    thresholds : array-like, shape (n_targets, n_features) or (n_features,), optional
        Per-coefficient thresholds; replace ``threshold`` when given. ``0`` = never thresholded.
    lower, upper : array-like, shape (n_targets, n_features) or (n_features,), optional
        Box on the coefficients (``-inf`` / ``+inf`` = unbounded; ``None`` = unbounded).
    constraint_lhs : array-like, shape (n_constraints, n_targets * n_features), optional
        ``C`` of the equality constraints ``C vec(coef) = d``.
    constraint_rhs : array-like, shape (n_constraints,), optional
        ``d``.
    constraint_order : {"target", "feature"}, default "target"
        Column layout of ``constraint_lhs`` (pysindy's meaning, see module docstring).
    max_iter : int, default 250
        Maximum SR3 iterations.
    tol : float, default 1e-10
        Convergence tolerance on ``||W_k - W_{k-1}||_F / nu``.
    unbias : bool, default True
        Refit on the support subject to box and equality constraints.
    normalize_columns : bool, default False
        Iterate on unit-norm columns (constraints and thresholds keep their meaning).
    copy_X : bool, default True
        Copy the data in :meth:`fit` (otherwise it may be overwritten).

    Attributes
    ----------
    coef_ : ndarray, shape (n_targets, n_features)
        Sparse, constraint-respecting coefficients.
    coef_full_ : ndarray, shape (n_targets, n_features)
        The relaxed variable ``xi`` at the last iteration (meets ``C vec(xi) = d``).
    ind_ : ndarray of bool, shape (n_targets, n_features)
        Support of the SR3 solution.
    history_ : list of ndarray, shape (n_targets, n_features)
        ``W`` per iteration; ``history_[0]`` is the initial least-squares guess (box-clipped).
    objective_history_ : list of float
        SR3 objective per iteration (normalised coordinates).
    n_iter_ : int
        Iterations run.
    converged_ : bool
        Whether the tolerance was met within ``max_iter``.
    """

    def __init__(
        self,
        threshold: float = 0.1,
        nu: float = 1.0,
        *,
        thresholds: ArrayLike | None = None,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        constraint_lhs: ArrayLike | None = None,
        constraint_rhs: ArrayLike | None = None,
        constraint_order: Literal["target", "feature"] = "target",
        max_iter: int = 250,
        tol: float = 1e-10,
        unbias: bool = True,
        normalize_columns: bool = False,
        copy_X: bool = True,
    ) -> None:
        super().__init__(max_iter=max_iter, normalize_columns=normalize_columns,
                         copy_X=copy_X, unbias=unbias)
        self.threshold = threshold
        self.nu = nu
        self.thresholds = thresholds
        self.lower = lower
        self.upper = upper
        self.constraint_lhs = constraint_lhs
        self.constraint_rhs = constraint_rhs
        self.constraint_order = constraint_order
        self.tol = tol

    # ------------------------------------------------------------------ settings
    def _per_coef(self, name: str, value: ArrayLike | None, fill: float, T: int,
                  p: int) -> NDArray:
        if value is None:
            return np.full((T, p), fill)
        a = np.asarray(value, dtype=float)
        if a.shape == (p,):
            a = np.broadcast_to(a, (T, p))
        if a.shape != (T, p):
            raise ValueError(f"{name} must have shape ({T}, {p}) (n_targets, n_features) "
                             f"or ({p},), got {a.shape}")
        if np.isnan(a).any():
            raise ValueError(f"{name} must not contain NaN")
        return np.array(a)

    def _check_scalars(self) -> None:
        thr, nu, tol = self.threshold, self.nu, self.tol
        if not (np.isscalar(thr) and np.isfinite(thr) and thr >= 0):
            raise ValueError(f"threshold must be a finite number >= 0, got {thr!r}")
        if not (np.isscalar(nu) and np.isfinite(nu) and nu > 0):
            raise ValueError(f"nu must be a finite number > 0, got {nu!r}")
        if not (np.isscalar(tol) and np.isfinite(tol) and tol > 0):
            raise ValueError(f"tol must be a finite number > 0, got {tol!r}")
        if not (isinstance(self.max_iter, int | np.integer) and self.max_iter >= 1):
            raise ValueError(f"max_iter must be an integer >= 1, got {self.max_iter!r}")
        if self.constraint_order not in ("target", "feature"):
            raise ValueError("constraint_order must be 'target' or 'feature', got "
                             f"{self.constraint_order!r}")

    def threshold_pattern(self, n_targets: int, n_features: int) -> NDArray:
        """Per-coefficient thresholds relative to ``threshold``, shape (n_targets, n_features).

        All ones without ``thresholds``; ``thresholds / threshold`` with them. A threshold grid
        value ``t`` (see :meth:`path_gram`) means thresholds ``t * pattern``.
        """
        self._check_scalars()
        if self.thresholds is None:
            return np.ones((n_targets, n_features))
        thr = self._per_coef("thresholds", self.thresholds, 0.0, n_targets, n_features)
        if np.any(thr < 0) or not np.all(np.isfinite(thr)):
            raise ValueError("thresholds must be finite and >= 0")
        if self.threshold == 0:
            if np.any(thr > 0):
                raise ValueError("with per-feature thresholds, threshold must be > 0 "
                                 "(it is their scale in a threshold sweep)")
            return np.zeros_like(thr)
        return thr / self.threshold

    def _normalised(self, G: ArrayLike, b: ArrayLike) -> tuple[_Normalised, int, int]:
        self._check_scalars()
        G = np.asarray(G, dtype=float)
        b = np.asarray(b, dtype=float)
        if G.ndim != 2 or G.shape[0] != G.shape[1]:
            raise ValueError(f"G must be square (n_features, n_features), got {G.shape}")
        p = G.shape[0]
        if b.ndim == 1:
            b = b[:, None]
        if b.shape[0] != p:
            raise ValueError(f"b must have shape ({p},) or ({p}, n_targets), got {b.shape}")
        if not (np.all(np.isfinite(G)) and np.all(np.isfinite(b))):
            raise ValueError("G and b must be finite")
        T = b.shape[1]
        lower = self._per_coef("lower", self.lower, -np.inf, T, p)
        upper = self._per_coef("upper", self.upper, np.inf, T, p)
        if np.any(lower > upper):
            i, j = np.argwhere(lower > upper)[0]
            raise ValueError(f"lower must be <= upper (target {i}, feature {j}: "
                             f"{lower[i, j]} > {upper[i, j]})")
        C, d = self._constraints(T, p)
        if self.normalize_columns:
            norms = np.sqrt(np.clip(np.diag(G), 0.0, None))
            norms[norms == 0] = 1.0
        else:
            norms = np.ones(p)
        Gn = G / np.outer(norms, norms)
        Gn = 0.5 * (Gn + Gn.T)
        prob = _Normalised(norms=norms, G=Gn, b=(b / norms[:, None]).T,
                           lower=lower * norms, upper=upper * norms,
                           C=C / np.tile(norms, T), d=d)
        return prob, T, p

    def _constraints(self, T: int, p: int) -> tuple[NDArray, NDArray]:
        if self.constraint_lhs is None and self.constraint_rhs is None:
            return np.zeros((0, T * p)), np.zeros(0)
        if self.constraint_lhs is None or self.constraint_rhs is None:
            raise ValueError("constraint_lhs and constraint_rhs must be given together")
        C = np.atleast_2d(np.asarray(self.constraint_lhs, dtype=float))
        d = np.atleast_1d(np.asarray(self.constraint_rhs, dtype=float)).ravel()
        if C.shape[1] != T * p or C.shape[0] != d.size:
            raise ValueError(f"constraint_lhs must have shape (n_constraints, {T * p}) "
                             f"(n_targets * n_features) and constraint_rhs "
                             f"(n_constraints,), got {C.shape} and {d.shape}")
        if not (np.all(np.isfinite(C)) and np.all(np.isfinite(d))):
            raise ValueError("constraint_lhs and constraint_rhs must be finite")
        if np.linalg.matrix_rank(C) < C.shape[0]:
            raise ValueError("constraint_lhs must have full row rank (redundant or "
                             "contradictory equality constraints)")
        if self.constraint_order == "feature":
            C = C.reshape(-1, p, T).transpose(0, 2, 1).reshape(-1, T * p)
        return C, d

    # ------------------------------------------------------------------ core
    @staticmethod
    def _iterate(fac: _Factor, prob: _Normalised, W: NDArray, thr: NDArray, max_iter: int,
                 tol: float, history: list | None = None,
                 ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """Run SR3 on a batch ``W`` (K, T, p) with thresholds ``thr`` (K, T, p), in place."""
        K = W.shape[0]
        nu = fac.nu
        thr2 = thr * thr
        lo, hi = prob.lower, prob.upper
        zero_ok = (lo <= 0) & (hi >= 0)
        xi = W.copy()
        n_iter = np.zeros(K, dtype=int)
        converged = np.zeros(K, dtype=bool)
        idx = np.arange(K)
        for _ in range(max_iter):
            Wa = W[idx]
            xa = fac.solve(prob.b[None] + Wa / nu)
            c = np.clip(xa, lo, hi)
            zero = zero_ok & (xa * xa - (c - xa) ** 2 <= thr2[idx])
            Wn = np.where(zero, 0.0, c)
            err = np.sqrt(((Wn - Wa) ** 2).sum(axis=(1, 2))) / nu
            W[idx] = Wn
            xi[idx] = xa
            n_iter[idx] += 1
            if history is not None:
                history.append((Wn[0].copy(), xa[0].copy()))
            done = err < tol
            converged[idx[done]] = True
            idx = idx[~done]
            if idx.size == 0:
                break
        return W, xi, n_iter, converged

    @staticmethod
    def _unbias_one(prob: _Normalised, W: NDArray, supp: NDArray | None = None) -> NDArray:
        """Least-squares refit of ``W`` (T, p) on its support (default ``W != 0``) with box and
        equality constraints; ``W`` seeds the active set."""
        T, p = W.shape
        if supp is None:
            supp = W != 0
        flat = np.flatnonzero(supp.ravel())  # target order
        if flat.size == 0 and prob.C.shape[0] == 0:
            return W
        t_of, j_of = np.divmod(flat, p)
        H = np.zeros((flat.size, flat.size))
        for t in range(T):
            sel = np.flatnonzero(t_of == t)
            H[np.ix_(sel, sel)] = prob.G[np.ix_(j_of[sel], j_of[sel])]
        g = prob.b[t_of, j_of]
        C = prob.C[:, flat]
        if prob.C.shape[0]:
            # a constraint touching only zeroed coefficients must already hold (0 = d)
            only_off = ~np.any(C != 0, axis=1)
            if np.any(np.abs(prob.d[only_off]) > 1e-12 * (1 + np.abs(prob.d[only_off]))):
                raise InfeasibleError("an equality constraint involves only thresholded "
                                      "coefficients")
        x = constrained_lstsq(H, g, lower=prob.lower[t_of, j_of], upper=prob.upper[t_of, j_of],
                              A=C if C.shape[0] else None, d=prob.d if C.shape[0] else None,
                              x0=W[t_of, j_of])
        out = np.zeros_like(W)
        out[t_of, j_of] = x
        return out

    def _initial_guess(self, prob: _Normalised) -> NDArray:
        """Least-squares solution (pysindy's start), clipped to the box, shape (T, p)."""
        x0 = np.linalg.lstsq(prob.G, prob.b.T, rcond=None)[0].T
        return np.clip(x0, prob.lower, prob.upper)

    def _objective(self, prob: _Normalised, yy: NDArray, xi: NDArray, W: NDArray,
                   lam: NDArray) -> float:
        rss = np.sum(yy) - 2 * np.sum(prob.b * xi) + np.einsum("ti,ij,tj->", xi, prob.G, xi)
        return float(0.5 * rss + np.sum(lam * (W != 0))
                     + 0.5 * np.sum((xi - W) ** 2) / self.nu)

    # ------------------------------------------------------------------ public
    def fit_gram(self, G: ArrayLike, b: ArrayLike, yy: ArrayLike | None = None,
                 n_rows: int | None = None, **kwargs: object) -> BoxSR3:
        """Fit from the normal-equation statistics.

        Parameters
        ----------
        G : array-like, shape (n_features, n_features)
            ``Theta^T Theta``.
        b : array-like, shape (n_features,) or (n_features, n_targets)
            ``Theta^T y``.
        yy : float or array-like, shape (n_targets,), optional
            ``y^T y`` per target (only for ``objective_history_``; 0 if omitted).
        n_rows : int, optional
            Number of rows behind ``G`` (recorded as ``n_rows_``).

        Returns
        -------
        self
        """
        if kwargs:
            raise TypeError(f"unexpected arguments {sorted(kwargs)}")
        prob, T, p = self._normalised(G, b)
        pattern = self.threshold_pattern(T, p)
        thr = (self.threshold * pattern * prob.norms)[None]
        fac = _Factor(prob.G, float(self.nu), prob.C, prob.d, T)
        W0 = self._initial_guess(prob)
        hist: list = []
        W, xi, n_iter, conv = self._iterate(fac, prob, W0[None].copy(), thr, self.max_iter,
                                            self.tol, history=hist)
        yyv = np.zeros(T) if yy is None else np.broadcast_to(np.asarray(yy, float), (T,))
        lam = (thr[0] ** 2) / (2 * self.nu)
        self.objective_history_ = [self._objective(prob, yyv, x, w, lam) for w, x in hist]
        self.history_ = [W0 / prob.norms] + [w / prob.norms for w, _ in hist]
        self.n_iter_ = int(n_iter[0])
        self.iters = self.n_iter_
        self.converged_ = bool(conv[0])
        if not self.converged_:
            warnings.warn(f"BoxSR3 did not converge after {self.max_iter} iterations "
                          f"(tol={self.tol:g}).", ConvergenceWarning, stacklevel=2)
        Wf = W[0]
        self.ind_ = Wf != 0
        if self.unbias:
            try:
                Wf = self._unbias_one(prob, Wf)
            except InfeasibleError as err:
                warnings.warn(f"BoxSR3 unbiasing skipped: {err}", stacklevel=2)
        lo, hi = prob.lower / prob.norms, prob.upper / prob.norms
        self.coef_ = np.clip(Wf / prob.norms, lo, hi)
        self.coef_full_ = xi[0] / prob.norms
        self.intercept_ = 0.0
        self.n_features_in_ = p
        self.n_rows_ = n_rows
        return self

    def refit_gram(self, G: ArrayLike, b: ArrayLike, support: ArrayLike) -> NDArray:
        """Least squares on a fixed support subject to this optimizer's box and equalities.

        Parameters
        ----------
        G : array-like, shape (n_features, n_features)
        b : array-like, shape (n_features,) or (n_features, n_targets)
        support : array-like of bool, shape (n_targets, n_features) or (n_features,)

        Returns
        -------
        coef : ndarray, shape (n_targets, n_features)
            Zero off the support; raises :class:`InfeasibleError` if the constraints cannot be
            met on this support.
        """
        prob, T, p = self._normalised(G, b)
        supp = np.asarray(support, dtype=bool)
        if supp.shape == (p,):
            supp = np.broadcast_to(supp, (T, p))
        if supp.shape != (T, p):
            raise ValueError(f"support must have shape ({T}, {p}), got {supp.shape}")
        # start inside the box on the support (the value only seeds the active set)
        W = np.where(supp, self._initial_guess(prob), 0.0)
        W = self._unbias_one(prob, W, supp)
        return np.clip(W / prob.norms, prob.lower / prob.norms, prob.upper / prob.norms)

    def path_gram(self, G: ArrayLike, b: ArrayLike, thresholds: ArrayLike,
                  ) -> tuple[NDArray, NDArray]:
        """Fits for several thresholds at this ``nu`` with ONE factorisation (model selection).

        Grid value ``t`` means per-coefficient thresholds ``t * threshold_pattern(...)``; with
        ``t = threshold`` the result equals :meth:`fit_gram`'s ``coef_``. The fits run as one
        batch, each stopping at its own convergence.

        Parameters
        ----------
        G : array-like, shape (n_features, n_features)
        b : array-like, shape (n_features,) or (n_features, n_targets)
        thresholds : array-like, shape (K,)
            Threshold grid (>= 0).

        Returns
        -------
        coef : ndarray, shape (K, n_targets, n_features)
            Final coefficients (unbiased if ``unbias``), original units.
        n_iter : ndarray of int, shape (K,)
        """
        ts = np.atleast_1d(np.asarray(thresholds, dtype=float))
        if ts.ndim != 1 or np.any(~np.isfinite(ts)) or np.any(ts < 0):
            raise ValueError("thresholds must be a 1-D array of finite values >= 0")
        prob, T, p = self._normalised(G, b)
        pattern = self.threshold_pattern(T, p) * prob.norms
        fac = _Factor(prob.G, float(self.nu), prob.C, prob.d, T)
        W0 = self._initial_guess(prob)
        K = ts.size
        W, _, n_iter, _ = self._iterate(fac, prob, np.repeat(W0[None], K, axis=0),
                                        ts[:, None, None] * pattern[None], self.max_iter,
                                        self.tol)
        if self.unbias:
            for k in range(K):
                try:
                    W[k] = self._unbias_one(prob, W[k])
                except InfeasibleError:
                    pass
        lo, hi = prob.lower / prob.norms, prob.upper / prob.norms
        return np.clip(W / prob.norms, lo, hi), n_iter
