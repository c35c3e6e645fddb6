"""Bagging that keeps the constraints: coefficient uncertainty from a moving-block bootstrap.

pysindy's ``EnsembleOptimizer`` resamples single rows and drops the optimizer's constraints; here
every bootstrap model is a full :class:`BoxSR3` fit (same box, equalities and thresholds), so each
sample respects the calibration constraints. Rows of an AFM trace (samples or weak-form test
functions) are correlated in time, so rows are drawn in contiguous blocks of ``block_size``
(moving-block bootstrap, Kuensch 1989): a bootstrap set is ``ceil(fraction * n / block_size)``
blocks whose start is uniform in ``[0, n - block_size]``. The draw is applied as integer row
weights (a row drawn twice counts twice), so a model costs one weighted Gram matrix, O(n p^2).
"""

from __future__ import annotations

import math
import warnings
from typing import final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning

from afmlearn.identify.optimizers.base import InfeasibleError
from afmlearn.identify.optimizers.sr3 import BoxSR3

__all__ = ["ConstrainedBagging", "block_bootstrap_weights"]


def block_bootstrap_weights(n_rows: int, block_size: int, n_blocks: int,
                            rng: np.random.Generator) -> NDArray:
    """Row multiplicities of one moving-block bootstrap draw, shape (n_rows,), sum
    ``n_blocks * block_size``."""
    starts = rng.integers(0, n_rows - block_size + 1, size=n_blocks)
    w = np.zeros(n_rows + 1)
    np.add.at(w, starts, 1.0)
    np.add.at(w, starts + block_size, -1.0)
    return np.cumsum(w[:-1])


@final
class ConstrainedBagging:
    """Moving-block bootstrap of a constrained SR3 fit.

    Parameters
    ----------
    optimizer : BoxSR3
        Fitted on every bootstrap set with all its settings and constraints.
    n_models : int, default 50
        Number of bootstrap models (>= 2).
    block_size : int, optional
        Rows per block (default ``round(n_rows ** (1/3))``, the usual rate for block bootstraps;
        set it to the correlation length of the rows, e.g. one drive period of samples).
    fraction : float, default 1.0
        Rows per bootstrap set as a fraction of ``n_rows`` (0 < fraction <= 1).
    seed : int, default 0
        Seed of ``numpy.random.default_rng``.
    fixed_support : bool, default False
        False: each model is a full SR3 fit (its support may change; gives
        ``inclusion_probability_``). True: each model refits the coefficients on the support of
        the full-data fit (constrained least squares), i.e. the uncertainty of the selected model.

    Attributes
    ----------
    estimator_ : BoxSR3
        The optimizer fitted on all rows.
    coef_samples_ : ndarray, shape (n_models, n_targets, n_features)
        Coefficients of every bootstrap model (each meets the box and equality constraints).
    coef_median_, coef_lo_, coef_hi_ : ndarray, shape (n_targets, n_features)
        Median and 2.5 / 97.5 % percentiles over models (these meet the box; a percentile of an
        equality-constrained combination need not meet the equality).
    inclusion_probability_ : ndarray, shape (n_targets, n_features)
        Fraction of models in which the coefficient is nonzero.
    block_size_ : int
    n_not_converged_ : int
        Bootstrap SR3 fits that hit ``max_iter``.
    """

    def __init__(self, optimizer: BoxSR3, *, n_models: int = 50, block_size: int | None = None,
                 fraction: float = 1.0, seed: int = 0, fixed_support: bool = False) -> None:
        self.optimizer = optimizer
        self.n_models = n_models
        self.block_size = block_size
        self.fraction = fraction
        self.seed = seed
        self.fixed_support = fixed_support

    def _check(self, n: int) -> int:
        if not isinstance(self.optimizer, BoxSR3):
            raise ValueError(f"optimizer must be a BoxSR3, got {type(self.optimizer).__name__}")
        if not (isinstance(self.n_models, int | np.integer) and self.n_models >= 2):
            raise ValueError(f"n_models must be an integer >= 2, got {self.n_models!r}")
        if not (np.isfinite(self.fraction) and 0 < self.fraction <= 1):
            raise ValueError(f"fraction must be in (0, 1], got {self.fraction!r}")
        L = max(1, round(n ** (1 / 3))) if self.block_size is None else self.block_size
        if not (isinstance(L, int | np.integer) and 1 <= L <= n):
            raise ValueError(f"block_size must be an integer in [1, n_rows={n}], got {L!r}")
        return int(L)

    def fit(self, Theta: ArrayLike, y: ArrayLike) -> ConstrainedBagging:
        """Fit the full-data model and ``n_models`` bootstrap models.

        Parameters
        ----------
        Theta : array-like, shape (n_rows, n_features)
            Library, rows in time order.
        y : array-like, shape (n_rows,) or (n_rows, n_targets)

        Returns
        -------
        self
        """
        X = np.asarray(Theta, dtype=float)
        Y = np.asarray(y, dtype=float)
        Y = Y[:, None] if Y.ndim == 1 else Y
        if X.ndim != 2 or Y.ndim != 2 or Y.shape[0] != X.shape[0]:
            raise ValueError(f"Theta (n_rows, n_features) and y (n_rows[, n_targets]) "
                             f"disagree: {X.shape}, {np.shape(y)}")
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
            raise ValueError("Theta and y must be finite (drop NaN rows first)")
        n = X.shape[0]
        L = self._check(n)
        n_blocks = math.ceil(self.fraction * n / L)
        rng = np.random.default_rng(self.seed)
        est = clone(self.optimizer).fit(X, Y)
        samples = np.empty((self.n_models, Y.shape[1], X.shape[1]))
        not_conv = 0
        for m in range(self.n_models):
            w = block_bootstrap_weights(n, L, n_blocks, rng)
            Xw = X * w[:, None]
            G, b = Xw.T @ X, Xw.T @ Y
            if self.fixed_support:
                try:
                    samples[m] = est.refit_gram(G, b, est.ind_)
                except InfeasibleError:
                    samples[m] = est.coef_
                continue
            opt = clone(self.optimizer)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                opt.fit_gram(G, b, None, int(w.sum()))
            not_conv += not opt.converged_
            samples[m] = opt.coef_
        self.estimator_ = est
        self.coef_samples_ = samples
        self.coef_median_ = np.median(samples, axis=0)
        self.coef_lo_, self.coef_hi_ = np.percentile(samples, [2.5, 97.5], axis=0)
        self.inclusion_probability_ = np.mean(samples != 0, axis=0)
        self.block_size_ = L
        self.n_not_converged_ = int(not_conv)
        return self
