"""Greedy forward selection of supports, scored like the SR3 grid (rolling CV, AICc, BIC).

Why next to SR3: in steady-state AFM data the force terms are nearly collinear (every candidate
is a pulse at the same phase of the orbit), so the dense least-squares solution that seeds SR3
and STLSQ consists of large, cancelling coefficients, and thresholding it keeps the wrong
terms. Forward selection adds, at each step, the term that lowers the constrained residual
most; it never passes through the ill-conditioned dense solution. Its nested supports join the
SR3 grid's candidates, and the Pareto front decides among all of them.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Sequence
from typing import final

import numpy as np
from numpy.typing import NDArray

from .optimizers import BoxSR3
from .selection import Candidate, information_criteria

__all__ = ["ForwardSelection", "cv_errors"]

FloatArray = NDArray[np.float64]


def _block_stats(theta: FloatArray, y: FloatArray, blocks: Sequence[tuple[int, int]]):
    gb = np.stack([theta[a:z].T @ theta[a:z] for a, z in blocks])
    bb = np.stack([theta[a:z].T @ y[a:z] for a, z in blocks])
    yy = np.array([y[a:z] @ y[a:z] for a, z in blocks])
    nr = np.array([z - a for a, z in blocks])
    rng = np.array([np.ptp(y[a:z]) if z > a else 1.0 for a, z in blocks])
    return gb, bb, yy, nr, np.where(rng > 0, rng, 1.0)


def cv_errors(opt: BoxSR3, theta: FloatArray, y: FloatArray,
              blocks: Sequence[tuple[int, int]], support: NDArray[np.bool_],
              prior: tuple[FloatArray, FloatArray] | None = None, stats=None) -> FloatArray:
    """Rolling (forward-chaining) validation NRMSE of a fixed support, shape (n_blocks - 1,).

    Fold ``f`` fits blocks ``0..f`` (plus ``(f+1)/n_blocks`` of the prior) and validates on
    block ``f + 1``; the error is RMSE / range of the validation target, as in `GridSearch`.
    """
    gb, bb, yy, nr, rng = stats if stats is not None else _block_stats(theta, y, blocks)
    nb = len(blocks)
    out = np.empty(nb - 1)
    gc, bc = np.cumsum(gb, axis=0), np.cumsum(bb, axis=0)
    for f in range(nb - 1):
        g, b = gc[f].copy(), bc[f].copy()
        if prior is not None:
            g += prior[0] * (f + 1) / nb
            b += prior[1] * (f + 1) / nb
        try:
            c = opt.refit_gram(g, b, support)[0]
        except (ValueError, np.linalg.LinAlgError):  # infeasible support on a short fold
            out[f] = np.inf
            continue
        v = f + 1
        rss = yy[v] - 2 * c @ bb[v] + c @ gb[v] @ c
        out[f] = np.sqrt(max(rss, 0.0) / nr[v]) / rng[v]
    return out


@final
class ForwardSelection:
    """Nested supports by greedy forward selection under the optimizer's boxes and priors.

    Parameters
    ----------
    optimizer : BoxSR3
        Supplies the boxes (``lower``/``upper``) used in every refit.
    always : sequence of int
        Feature indices in every support (the lever's own ``x'``, ``x`` and the drive).
    max_terms : int
        Largest number of added terms (>= 1).
    cross_validate : bool
        Compute the rolling CV errors of each support (False: NaN, faster).
    exhaustive : int
        Supports of up to this many added terms are found by enumerating every subset; the
        greedy steps start from the best of them.

    Attributes
    ----------
    candidates_ : list of Candidate
        One per support size (``threshold`` and ``nu`` are NaN), in order of size.
    path_ : list of int
        Feature indices in the order they were added.
    """

    def __init__(self, optimizer: BoxSR3, *, always: Sequence[int], max_terms: int = 6,
                 cross_validate: bool = True, exhaustive: int = 2) -> None:
        self.optimizer = optimizer
        self.always = always
        self.max_terms = max_terms
        self.cross_validate = cross_validate
        self.exhaustive = exhaustive

    def fit(self, theta: FloatArray, y: FloatArray, blocks: Sequence[tuple[int, int]],
            prior: tuple[FloatArray, FloatArray] | None = None) -> ForwardSelection:
        """Run the selection on rows ``theta`` (n, p), ``y`` (n,) cut into ``blocks``."""
        if not (isinstance(self.max_terms, int) and self.max_terms >= 1):
            raise ValueError(f"max_terms must be an integer >= 1, got {self.max_terms!r}")
        n, p = theta.shape
        G = theta.T @ theta
        b = theta.T @ y
        if prior is not None:
            G, b = G + prior[0], b + prior[1]
        dead = np.all(theta == 0, axis=0)
        support = np.zeros(p, bool)
        support[list(self.always)] = True
        stats = _block_stats(theta, y, blocks) if self.cross_validate else None
        cands: list[Candidate] = []

        def rss_of(c: FloatArray) -> float:
            # direct residual: yy - 2 c.b + c.G.c cancels catastrophically near a perfect fit
            r = y - theta @ c
            return float(r @ r)

        def fit(supp: NDArray[np.bool_]) -> FloatArray | None:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    return self.optimizer.refit_gram(G, b, supp)[0]
            except (ValueError, np.linalg.LinAlgError):  # infeasible support
                return None

        def candidate(supp: NDArray[np.bool_], c: FloatArray) -> Candidate:
            errs = (cv_errors(self.optimizer, theta, y, blocks, supp, prior, stats)
                    if self.cross_validate else np.full(len(blocks) - 1, np.nan))
            rss = rss_of(c)
            k = int(np.count_nonzero(c))
            aicc, bic = information_criteria(rss, n, k)
            return Candidate(threshold=float("nan"), nu=float("nan"), coef=c[None].copy(),
                             support=(c != 0)[None], n_terms=k, cv_error=float(errs.mean()),
                             cv_error_std=float(errs.std()), fold_errors=errs, rss=rss,
                             aicc=aicc, bic=bic, n_iter=0)

        c0 = fit(support)
        if c0 is not None:
            cands.append(candidate(support, c0))
        # best subsets of up to `exhaustive` added terms by enumeration (cheap: unconstrained
        # solves on the small Gram blocks, the constrained refit only when a box is violated),
        # then greedy steps with swaps from the best of them
        free = [int(j) for j in np.flatnonzero(~support & ~dead)]
        base = np.flatnonzero(support)
        lo = np.asarray(self.optimizer.lower, float) if self.optimizer.lower is not None \
            else np.full(p, -np.inf)
        hi = np.asarray(self.optimizer.upper, float) if self.optimizer.upper is not None \
            else np.full(p, np.inf)
        lo, hi = lo.reshape(-1)[:p], hi.reshape(-1)[:p]
        start = 0
        for k in range(1, min(self.exhaustive, self.max_terms, len(free)) + 1):
            best_k: tuple[float, NDArray[np.bool_], FloatArray] | None = None
            for combo in itertools.combinations(free, k):
                idx = np.concatenate([base, combo])
                try:
                    sol = np.linalg.solve(G[np.ix_(idx, idx)], b[idx])
                except np.linalg.LinAlgError:
                    continue
                c = np.zeros(p)
                c[idx] = sol
                if np.any(c[idx] < lo[idx] - 1e-12) or np.any(c[idx] > hi[idx] + 1e-12):
                    trial = np.zeros(p, bool)
                    trial[idx] = True
                    cc = fit(trial)
                    if cc is None:
                        continue
                    c = cc
                r = rss_of(c)
                if best_k is None or r < best_k[0]:
                    trial = np.zeros(p, bool)
                    trial[idx] = True
                    best_k = (r, trial, c)
            if best_k is None:
                break
            cands.append(candidate(best_k[1], best_k[2]))
            support = best_k[1].copy()
            start = k
        path = [int(j) for j in np.flatnonzero(support) if int(j) not in set(base)]
        for _ in range(start, self.max_terms):
            best, best_rss, best_c = -1, np.inf, None
            for j in np.flatnonzero(~support & ~dead):
                trial = support.copy()
                trial[j] = True
                c = fit(trial)
                if c is None:
                    continue
                r = rss_of(c)
                if r < best_rss:
                    best, best_rss, best_c = int(j), r, c
            if best < 0 or best_c is None:
                break
            support[best] = True
            path.append(best)
            best_rss = rss_of(best_c)
            support, best_c = self._swap(support, best_c, best_rss, fit, rss_of, dead)
            cands.append(candidate(support, best_c))
        self.candidates_ = cands
        self.path_ = path
        return self

    def _swap(self, support, coef, rss, fit, rss_of, dead, max_passes: int = 4):
        """Replace one added term by another while that lowers the residual (forward-backward
        refinement: a greedy path can lock in a term that only mimics a pair of true ones)."""
        fixed = set(int(i) for i in self.always)
        for _ in range(max_passes):
            improved = False
            for i in [int(i) for i in np.flatnonzero(support) if int(i) not in fixed]:
                for j in np.flatnonzero(~support & ~dead):
                    trial = support.copy()
                    trial[i], trial[j] = False, True
                    c = fit(trial)
                    if c is None:
                        continue
                    r = rss_of(c)
                    if r < rss * (1 - 1e-9):
                        support, coef, rss, improved = trial, c, r, True
                        break
            if not improved:
                break
        return support, coef
