"""Model selection for :class:`BoxSR3`: rolling cross-validation over a threshold x nu grid,
Pareto front, knee and information criteria.

Cross-validation is forward chaining over time-ordered rows: the rows are cut into
``n_folds + 1`` contiguous blocks and fold ``k`` (k = 1..n_folds) trains on blocks ``0..k-1`` and
validates on block ``k``; nothing from the future is used to predict the past. Every fit works on
Gram matrices: the block statistics ``Theta_B^T Theta_B``, ``Theta_B^T y_B``, ``y_B^T y_B`` are
computed once (O(n p^2) in total), a fold's training Gram is a cumulative sum of block Grams, and
the whole threshold grid of one ``(fold, nu)`` is one batched SR3 run on one Cholesky factor
(:meth:`BoxSR3.path_gram`), so the grid costs O(folds x nus x (p^3 + iterations x p^2)),
independent of the number of rows.

Validation error of a fold: NRMSE = RMS(y - Theta coef) / (max(y) - min(y)) over the validation
block (design.md §4), averaged over targets. The candidate's coefficients are refitted on all
rows; AICc and BIC use that full fit with ``k = n_terms`` and ``n = n_rows * n_targets``. Rows of a
weak formulation are correlated, so ``n`` overstates the independent information and both
criteria lean to richer models: use them as a second opinion beside the knee.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import clone

from afmlearn.identify.optimizers.sr3 import BoxSR3

logger = logging.getLogger(__name__)

__all__ = [
    "Candidate",
    "GridSearch",
    "best_by_ic",
    "default_nu_grid",
    "default_threshold_grid",
    "knee",
    "knee_one_se",
    "knee_point",
    "merge_supports",
    "pareto_front",
    "profile_interval",
    "rolling_blocks",
]


def default_threshold_grid(q: float, n: int = 10, *, low: float = 0.25,
                           high: float = 50.0) -> NDArray:
    """Geometric threshold grid from ``low/Q`` to ``high/Q`` (dimensionless coefficients).

    ``1/Q`` is the smallest coefficient the calibration says is real (damping of ``x'``);
    physics.md §5 starts the sweep there. Going down to ``Q^-1/4`` lets terms of the order of
    the damping force survive (the sparse end of the Pareto front must be reachable from the
    dense end), and ``50/Q`` (0.1-0.5 for Q = 100-500) leaves only O(1) coefficients
    (stiffness, drive, contact). Ten points over these 2.3 decades are steps of ~1.8x.

    Parameters
    ----------
    q : float
        Quality factor (> 0).
    n : int
        Number of grid points (>= 1).

    Returns
    -------
    ndarray, shape (n,)
    """
    if not (np.isfinite(q) and q > 0):
        raise ValueError(f"q must be a finite number > 0, got {q!r}")
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not (0 < low < high):
        raise ValueError(f"need 0 < low < high, got low={low}, high={high}")
    return np.geomspace(low / q, high / q, n)


def default_nu_grid(n: int = 5, *, scale: float = 1.0) -> NDArray:
    """Geometric relaxation grid ``geomspace(0.1, 10, n) / scale``.

    ``nu`` competes with the Gram matrix in the xi-step ``(G + I/nu) xi = b + W/nu``: for
    ``nu * eig(G) >> 1`` SR3 reduces to thresholded least squares, for ``<< 1`` xi stays close to
    W. ``scale`` should be a typical diagonal entry of the Gram matrix the optimizer iterates on:
    ``1`` with ``normalize_columns=True`` (unit columns), ``mean(diag(Theta^T Theta))`` otherwise.
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a finite number > 0, got {scale!r}")
    return np.geomspace(0.1, 10.0, n) / scale


def rolling_blocks(n_rows: int, n_folds: int) -> list[tuple[int, int]]:
    """Cut ``n_rows`` time-ordered rows into ``n_folds + 1`` contiguous blocks ``[start, stop)``."""
    if n_folds < 1:
        raise ValueError(f"n_folds must be >= 1, got {n_folds}")
    if n_rows < 2 * (n_folds + 1):
        raise ValueError(f"need at least {2 * (n_folds + 1)} rows for {n_folds} folds, "
                         f"got {n_rows}")
    edges = np.linspace(0, n_rows, n_folds + 2).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


@final
@dataclass
class Candidate:
    """One fitted model of the grid.

    Attributes
    ----------
    threshold, nu : float
        Grid point (threshold in coefficient units; per-feature thresholds are
        ``threshold * optimizer.threshold_pattern``).
    coef : ndarray, shape (n_targets, n_features)
        Coefficients refitted on all rows.
    support : ndarray of bool, shape (n_targets, n_features)
    n_terms : int
        Number of nonzero coefficients.
    cv_error, cv_error_std : float
        Mean and standard deviation over folds of the validation NRMSE.
    fold_errors : ndarray, shape (n_folds,)
    rss : float
        Residual sum of squares of the full fit (all targets).
    aicc, bic : float
        Information criteria of the full fit (see module docstring).
    n_iter : int
        SR3 iterations of the full fit.
    scores : dict[str, float]
        Further objectives filled in by the caller (to minimise, e.g. ``"state_error"``,
        ``"force_error"``); :func:`knee` reads them by name.
    """

    threshold: float
    nu: float
    coef: NDArray
    support: NDArray
    n_terms: int
    cv_error: float
    cv_error_std: float
    fold_errors: NDArray
    rss: float
    aicc: float
    bic: float
    n_iter: int
    scores: dict[str, float] = field(default_factory=dict)

    def objective(self, name: str) -> float:
        """The value of an attribute (``"cv_error"``, ``"aicc"``, ...) or of ``scores[name]``."""
        if name in self.scores:
            return float(self.scores[name])
        if name in ("n_terms", "cv_error", "cv_error_std", "rss", "aicc", "bic", "threshold",
                    "nu"):
            return float(getattr(self, name))
        raise KeyError(f"unknown objective {name!r} (not an attribute, not in scores)")


def information_criteria(rss: float, n: int, k: int) -> tuple[float, float]:
    """AICc and BIC of a Gaussian least-squares fit with ``k`` parameters and ``n`` residuals."""
    rss = max(rss, np.finfo(float).tiny * n)
    ll = n * np.log(rss / n)
    aic = ll + 2 * k
    aicc = aic + 2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else np.inf
    return float(aicc), float(ll + k * np.log(n))


def pareto_front(points: ArrayLike) -> NDArray:
    """Indices of the non-dominated rows of ``points`` (all objectives minimised).

    Row ``a`` dominates ``b`` if ``a <= b`` in every column and ``a < b`` in one. Equal rows do not
    dominate each other (both are kept).

    Parameters
    ----------
    points : array-like, shape (n, k)

    Returns
    -------
    ndarray of int, sorted
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2:
        raise ValueError(f"points must be 2-D (n, k), got shape {P.shape}")
    if np.isnan(P).any():
        raise ValueError("points must not contain NaN")
    keep = []
    for i in range(P.shape[0]):
        le = np.all(P <= P[i], axis=1) & np.any(P < P[i], axis=1)
        if not le.any():
            keep.append(i)
    return np.asarray(keep, dtype=int)


def knee_point(n_terms: ArrayLike, errors: ArrayLike) -> int:
    """Knee of the Pareto front of (n_terms, errors...) (Kneedle, Satopaa et al. 2011).

    Rule: take the Pareto front of ``[n_terms, errors]``; scale ``n_terms`` and each
    ``log10(error)`` column to [0, 1] over the front and average the error columns into one error
    ``e``. Errors are compared on a log scale because validation errors fall by decades down to
    the noise floor: on a linear scale the first large drop hides the later ones (a model missing
    a small term would look like the knee). A = sparsest
    front point (ties: lower ``e``), B = most accurate (lowest ``e``; ties: fewer terms). Among
    front points with ``n_terms`` between A's and B's, the knee is the one farthest BELOW the
    chord A-B (largest ``chord(s) - e``; ties: fewer terms). If no point lies below the chord
    (straight or concave trade-off: no sharp drop), B is returned.

    Parameters
    ----------
    n_terms : array-like, shape (n,)
    errors : array-like, shape (n,) or (n, k)
        Objectives to minimise.

    Returns
    -------
    int
        Index into the inputs.
    """
    s_all = np.asarray(n_terms, dtype=float).ravel()
    E_all = np.asarray(errors, dtype=float)
    if E_all.ndim == 1:
        E_all = E_all[:, None]
    if E_all.shape[0] != s_all.size or s_all.size == 0:
        raise ValueError("n_terms and errors must have the same (nonzero) number of rows")
    if np.any(E_all < 0) or np.isnan(E_all).any():
        raise ValueError("errors must be >= 0 (objectives to minimise, e.g. 1 - accuracy)")
    E_all = np.log10(np.maximum(E_all, 1e-300))
    front = pareto_front(np.column_stack([s_all, E_all]))
    s, E = s_all[front], E_all[front]
    span = E.max(axis=0) - E.min(axis=0)
    e = np.mean(np.where(span > 0, (E - E.min(axis=0)) / np.where(span > 0, span, 1), 0.0),
                axis=1)
    order = np.lexsort((e, s))  # by n_terms, then error
    a = order[0]
    b = np.lexsort((s, e))[0]
    if s[b] <= s[a]:
        return int(front[b])
    chord = e[a] + (e[b] - e[a]) * (s - s[a]) / (s[b] - s[a])
    inside = (s >= s[a]) & (s <= s[b])
    dist = np.where(inside, chord - e, -np.inf)
    best = dist.max()
    if best <= 1e-12:
        return int(front[b])
    ties = np.flatnonzero(dist >= best - 1e-12)
    return int(front[ties[np.lexsort((e[ties], s[ties]))[0]]])


def knee(candidates: Sequence[Candidate], objectives: Sequence[str] = ("cv_error",)) -> int:
    """Index of the knee candidate (:func:`knee_point` on ``n_terms`` and ``objectives``).

    ``objectives`` name Candidate attributes or keys of ``Candidate.scores``, all minimised
    (e.g. ``("cv_error",)`` or ``("state_error", "force_error")`` for the 3-D front).
    """
    if not candidates:
        raise ValueError("candidates must not be empty")
    if not objectives:
        raise ValueError("objectives must name at least one error")
    n_terms = [c.n_terms for c in candidates]
    errs = [[c.objective(o) for o in objectives] for c in candidates]
    return knee_point(n_terms, errs)


def best_by_ic(candidates: Sequence[Candidate],
               criterion: Literal["aicc", "bic"] = "aicc") -> int:
    """Index of the candidate with the lowest information criterion (ties: fewer terms)."""
    if criterion not in ("aicc", "bic"):
        raise ValueError(f"criterion must be 'aicc' or 'bic', got {criterion!r}")
    if not candidates:
        raise ValueError("candidates must not be empty")
    keys = [(getattr(c, criterion), c.n_terms, c.cv_error) for c in candidates]
    return min(range(len(candidates)), key=keys.__getitem__)


@final
class GridSearch:
    """Threshold x nu grid of :class:`BoxSR3` fits with rolling cross-validation.

    Parameters
    ----------
    optimizer : BoxSR3
        Template: its constraints, per-feature threshold pattern, ``max_iter``, ``tol``,
        ``unbias`` and ``normalize_columns`` are used; ``threshold`` and ``nu`` are swept.
    thresholds : array-like, shape (n_thresholds,)
        Threshold grid (>= 0), e.g. :func:`default_threshold_grid`.
    nus : array-like, shape (n_nus,)
        Relaxation grid (> 0), e.g. :func:`default_nu_grid`.
    n_folds : int, default 10
        Rolling folds (>= 1).
    progress : bool, default False
        Print one line per fold to stderr.

    Attributes
    ----------
    candidates_ : list of Candidate
        One per distinct support (the best ``cv_error`` of each), sorted by
        ``(n_terms, cv_error)``.
    all_candidates_ : list of Candidate
        Every grid point, threshold-major (``index = i_threshold * n_nus + i_nu``).
    cv_error_grid_, n_terms_grid_ : ndarray, shape (n_thresholds, n_nus)
    blocks_ : list of (int, int)
        Row ranges of the ``n_folds + 1`` blocks.
    """

    def __init__(self, optimizer: BoxSR3, thresholds: ArrayLike, nus: ArrayLike, *,
                 n_folds: int = 10, progress: bool = False) -> None:
        self.optimizer = optimizer
        self.thresholds = thresholds
        self.nus = nus
        self.n_folds = n_folds
        self.progress = progress

    def _grids(self) -> tuple[NDArray, NDArray]:
        if not isinstance(self.optimizer, BoxSR3):
            raise ValueError(f"optimizer must be a BoxSR3, got {type(self.optimizer).__name__}")
        ts = np.atleast_1d(np.asarray(self.thresholds, dtype=float))
        nus = np.atleast_1d(np.asarray(self.nus, dtype=float))
        if ts.ndim != 1 or ts.size == 0 or np.any(~np.isfinite(ts)) or np.any(ts < 0):
            raise ValueError("thresholds must be a non-empty 1-D array of finite values >= 0")
        if nus.ndim != 1 or nus.size == 0 or np.any(~np.isfinite(nus)) or np.any(nus <= 0):
            raise ValueError("nus must be a non-empty 1-D array of finite values > 0")
        if not (isinstance(self.n_folds, int | np.integer) and self.n_folds >= 1):
            raise ValueError(f"n_folds must be an integer >= 1, got {self.n_folds!r}")
        return ts, nus

    def fit(self, Theta: ArrayLike, y: ArrayLike) -> GridSearch:
        """Run the grid.

        Parameters
        ----------
        Theta : array-like, shape (n_rows, n_features)
            Library, rows in time order.
        y : array-like, shape (n_rows,) or (n_rows, n_targets)

        Returns
        -------
        self
        """
        ts, nus = self._grids()
        X = np.asarray(Theta, dtype=float)
        Y = np.asarray(y, dtype=float)
        Y = Y[:, None] if Y.ndim == 1 else Y
        if X.ndim != 2 or Y.ndim != 2 or Y.shape[0] != X.shape[0]:
            raise ValueError(f"Theta (n_rows, n_features) and y (n_rows[, n_targets]) "
                             f"disagree: {X.shape}, {np.shape(y)}")
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
            raise ValueError("Theta and y must be finite (drop NaN rows first)")
        n, p = X.shape
        T = Y.shape[1]
        blocks = rolling_blocks(n, self.n_folds)
        nb = len(blocks)
        Gb = np.empty((nb, p, p))
        bb = np.empty((nb, p, T))
        yyb = np.empty((nb, T))
        nrows = np.empty(nb, dtype=int)
        yr = np.empty((nb, T))
        for i, (a, z) in enumerate(blocks):
            Xa, Ya = X[a:z], Y[a:z]
            Gb[i] = Xa.T @ Xa
            bb[i] = Xa.T @ Ya
            yyb[i] = np.einsum("ij,ij->j", Ya, Ya)
            nrows[i] = z - a
            yr[i] = Ya.max(axis=0) - Ya.min(axis=0)
        Gc, bc = np.cumsum(Gb, axis=0), np.cumsum(bb, axis=0)
        K, V = ts.size, nus.size
        fold_err = np.empty((K, V, self.n_folds))
        full_coef = np.empty((K, V, T, p))
        full_iter = np.empty((K, V), dtype=int)
        for f in range(self.n_folds + 1):
            train = f if f < self.n_folds else nb - 1  # last pass: all rows
            for v, nu in enumerate(nus):
                opt = clone(self.optimizer).set_params(nu=float(nu))
                coef, n_iter = opt.path_gram(Gc[train], bc[train], ts)
                if f == self.n_folds:
                    full_coef[:, v], full_iter[:, v] = coef, n_iter
                    continue
                val = f + 1
                rss = (yyb[val][None] - 2 * np.einsum("ktp,pt->kt", coef, bb[val])
                       + np.einsum("ktp,pq,ktq->kt", coef, Gb[val], coef))
                rmse = np.sqrt(np.clip(rss, 0.0, None) / nrows[val])
                rng = np.where(yr[val] > 0, yr[val], 1.0)
                fold_err[:, v, f] = np.mean(rmse / rng[None], axis=1)
            if self.progress:
                logger.info("GridSearch: fold %d/%d done", f + 1, self.n_folds + 1)
        G_all, b_all, yy_all = Gc[-1], bc[-1], yyb.sum(axis=0)
        cands = []
        for k, t in enumerate(ts):
            for v, nu in enumerate(nus):
                c = full_coef[k, v]
                rss = float(np.sum(yy_all) - 2 * np.einsum("tp,pt->", c, b_all)
                            + np.einsum("tp,pq,tq->", c, G_all, c))
                supp = c != 0
                kterms = int(supp.sum())
                aicc, bic = information_criteria(max(rss, 0.0), n * T, kterms)
                errs = fold_err[k, v]
                cands.append(Candidate(threshold=float(t), nu=float(nu), coef=c.copy(),
                                       support=supp, n_terms=kterms,
                                       cv_error=float(errs.mean()),
                                       cv_error_std=float(errs.std()), fold_errors=errs.copy(),
                                       rss=rss, aicc=aicc, bic=bic,
                                       n_iter=int(full_iter[k, v])))
        best: dict[bytes, Candidate] = {}
        for c in cands:
            key = np.packbits(c.support).tobytes()
            if key not in best or c.cv_error < best[key].cv_error:
                best[key] = c
        self.all_candidates_ = cands
        self.candidates_ = sorted(best.values(), key=lambda c: (c.n_terms, c.cv_error))
        self.cv_error_grid_ = fold_err.mean(axis=2)
        self.n_terms_grid_ = np.array([c.n_terms for c in cands]).reshape(K, V)
        self.blocks_ = blocks
        return self


#: relative CV improvement below which extra terms are never worth it (see knee_one_se)
_PRACTICAL = 0.01


def knee_one_se(cands: list[Candidate], objectives: tuple[str, ...]) -> int:
    """The knee: the sparsest front member within one standard error of the best CV error.

    The front is the Pareto front of ``(n_terms, *objectives)``. On it, the choice is the
    one-standard-error rule (Hastie, Tibshirani & Friedman, section 7.10) with paired folds:
    the fewest terms whose fold errors exceed the best candidate's by at most one standard
    error of the paired difference (the folds share their noise, so pairing removes the
    block-to-block scatter common to every candidate), or by at most 1 % per term it drops
    (`_PRACTICAL`), and this against every denser member of the front, not only the best
    (a dense best would otherwise excuse dropping a real term). The per-term tolerance is
    there because the denoised state is one estimate shared by every fold (and, on nearly
    noiseless data, a truncated series), so its error is a systematic residual that
    cross-validation cannot tell from signal; dense models fit part of it and look
    "significant" by a few per cent. Measured on a Lennard-Jones orbit (1 % noise):
    13 terms beat the true single ``z^-2`` by 2 % in CV error at equal force accuracy.
    This is where the error curve stops falling beyond its own noise. (Kneedle's geometric
    elbow, ``selection.knee_point``, stops after the first contact term, because one term
    removes most of the error; the second, e.g. the adhesion, is still far outside the
    noise.) Ties go to the lower CV error.
    """
    pts = np.array([[c.n_terms, *[c.objective(o) for o in objectives]] for c in cands])
    front = [int(i) for i in pareto_front(pts)]
    best = min(front, key=lambda i: cands[i].cv_error)

    def as_good(i: int, j: int) -> bool:
        """Candidate ``i`` is within tolerance of the denser candidate ``j``."""
        d = cands[i].fold_errors - cands[j].fold_errors
        if d.size < 2 or not np.all(np.isfinite(d)):
            return i == j
        extra = max(cands[j].n_terms - cands[i].n_terms, 1)
        tol = max(float(d.std(ddof=1)) / np.sqrt(d.size),
                  _PRACTICAL * extra * float(cands[j].fold_errors.mean()))
        return float(d.mean()) <= tol

    def within(i: int) -> bool:
        # as good as every denser front member: no added term may buy more than the
        # tolerance per term (else a dense best would excuse dropping a real term)
        return all(as_good(i, j) for j in front
                   if cands[j].n_terms > cands[i].n_terms) or i == best

    ok = [i for i in front if within(i)]
    return min(ok, key=lambda i: (cands[i].n_terms, cands[i].cv_error))


def merge_supports(*groups: list[Candidate]) -> list[Candidate]:
    """One candidate per distinct support (lowest cv_error), sorted by (n_terms, cv_error)."""
    best: dict[bytes, Candidate] = {}
    for group in groups:
        for c in group:
            key = np.packbits(c.support).tobytes()
            if key not in best or c.cv_error < best[key].cv_error:
                best[key] = c
    return sorted(best.values(), key=lambda c: (c.n_terms, c.cv_error))


def profile_interval(profile: NDArray, n_rows: int,
                      level: float = 3.841) -> tuple[float, float]:
    """Profile-likelihood interval of a parameter from its residual profile.

    ``profile`` shape (n, 2): ``(value, RSS)``. With Gaussian rows the likelihood-ratio
    statistic is ``n_rows log(RSS / RSS_min)``; values with it below ``level`` (3.841: 95 %
    for one parameter, chi-square) form the interval (its ends are the extreme grid values
    inside, so an interval reaching the grid's ends means "not bounded by the data").
    """
    v, r = profile[:, 0], profile[:, 1]
    ok = np.isfinite(r)
    if not ok.any():
        return (math.nan, math.nan)
    lr = n_rows * np.log(r[ok] / r[ok].min())
    inside = v[ok][lr <= level]
    return (float(inside.min()), float(inside.max()))
