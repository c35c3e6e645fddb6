"""Rolling cross-validation grid, Pareto front, knee and information criteria."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from afmlearn.identify.optimizers import BoxSR3
from afmlearn.identify.selection import (
    Candidate,
    GridSearch,
    best_by_ic,
    default_nu_grid,
    default_threshold_grid,
    knee,
    knee_point,
    pareto_front,
    rolling_blocks,
)


def _problem(seed=0, n=1200, p=8):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, p))
    xi = np.zeros(p)
    xi[[0, 1, 3, 5]] = [-0.02, -1.0, 0.6, 0.08]
    y = X @ xi + 0.01 * rng.normal(size=n)
    lo = np.full(p, -np.inf)
    hi = np.full(p, np.inf)
    lo[:2], hi[:2] = [-0.023, -1.15], [-0.017, -0.85]
    return X, y, xi, lo, hi


def test_rolling_blocks_partition_in_time_order():
    b = rolling_blocks(103, 10)
    assert len(b) == 11 and b[0][0] == 0 and b[-1][1] == 103
    assert all(b[i][1] == b[i + 1][0] for i in range(10))
    assert max(z - a for a, z in b) - min(z - a for a, z in b) <= 1
    with pytest.raises(ValueError, match="rows"):
        rolling_blocks(15, 10)
    with pytest.raises(ValueError, match="n_folds"):
        rolling_blocks(100, 0)


def test_default_grids():
    g = default_threshold_grid(200.0)
    assert g.size == 10 and g[0] == pytest.approx(0.25 / 200) and g[-1] == pytest.approx(0.25)
    np.testing.assert_allclose(g[1:] / g[:-1], g[1] / g[0])
    with pytest.raises(ValueError, match="q"):
        default_threshold_grid(0.0)
    nu = default_nu_grid(5, scale=4.0)
    assert nu[0] == pytest.approx(0.025) and nu[-1] == pytest.approx(2.5)


def test_pareto_front_matches_brute_force():
    rng = np.random.default_rng(1)
    P = np.column_stack([rng.integers(1, 8, 60), rng.random(60), rng.random(60)])
    P[5] = P[6]  # duplicates: both kept or both dropped
    front = set(pareto_front(P).tolist())
    for i in range(len(P)):
        dominated = any(np.all(P[j] <= P[i]) and np.any(P[j] < P[i]) for j in range(len(P)))
        assert (i in front) == (not dominated)


def test_knee_point_rules():
    terms = np.array([1, 2, 3, 4, 5, 6])
    err = np.array([1.0, 0.6, 0.05, 0.04, 0.035, 0.03])  # sharp drop at 3 terms
    assert knee_point(terms, err) == 2
    # dominated points are ignored
    assert knee_point(np.r_[terms, 3], np.r_[err, 0.5]) == 2
    # straight trade-off (on the log scale): no knee -> most accurate
    assert knee_point([1, 2, 3], [1.0, 0.1, 0.01]) == 2
    # a later drop to the noise floor is not hidden by the first one (log scale)
    assert knee_point([2, 3, 4, 5, 6], [0.095, 0.0126, 0.0016, 0.00159, 0.00158]) == 2
    # tie in distance below the chord -> fewer terms
    assert knee_point([1, 2, 3, 4], 10.0 ** np.array([0.0, -1.5, -2.5, -3.0])) == 1
    with pytest.raises(ValueError, match="errors"):
        knee_point([1, 2], [0.1, -0.1])
    # 3-D front: errors averaged after scaling
    e2 = np.column_stack([err, err[::-1] * 0 + err])
    assert knee_point(terms, e2) == 2


def test_best_by_ic_and_knee_use_scores():
    def cand(k, cv, aicc, **scores):
        return Candidate(threshold=0.1, nu=1.0, coef=np.zeros((1, 3)),
                         support=np.zeros((1, 3), bool), n_terms=k, cv_error=cv,
                         cv_error_std=0.0, fold_errors=np.zeros(2), rss=1.0, aicc=aicc,
                         bic=aicc, n_iter=1, scores=scores)
    cs = [cand(1, 1.0, 5.0, force_error=0.9), cand(2, 0.1, 1.0, force_error=0.1),
          cand(3, 0.09, 1.0, force_error=0.09), cand(4, 0.085, 2.0, force_error=0.01)]
    assert best_by_ic(cs) == 1  # tie at 1.0 -> fewer terms
    assert knee(cs) == 1
    assert knee(cs, objectives=("cv_error", "force_error")) == 1
    with pytest.raises(KeyError):
        knee(cs, objectives=("nope",))
    with pytest.raises(ValueError, match="criterion"):
        best_by_ic(cs, criterion="aic")


def test_grid_search_matches_plain_reference():
    """Fold errors from Gram sums equal fits on the raw rows; candidates equal full fits."""
    X, y, _, lo, hi = _problem()
    opt = BoxSR3(lower=lo, upper=hi, normalize_columns=True, max_iter=300)
    ts = default_threshold_grid(50.0, n=4)
    nus = [0.3, 3.0]
    gs = GridSearch(opt, ts, nus, n_folds=10).fit(X, y)
    blocks = gs.blocks_
    i_t, i_nu = 2, 1
    c = gs.all_candidates_[i_t * len(nus) + i_nu]
    errs = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for f in range(10):
            tr, va = slice(0, blocks[f][1]), slice(*blocks[f + 1])
            m = BoxSR3(ts[i_t], nus[i_nu], lower=lo, upper=hi, normalize_columns=True,
                       max_iter=300).fit(X[tr], y[tr])
            r = y[va] - X[va] @ m.coef_[0]
            errs.append(np.sqrt(np.mean(r**2)) / np.ptp(y[va]))
        full = BoxSR3(ts[i_t], nus[i_nu], lower=lo, upper=hi, normalize_columns=True,
                      max_iter=300).fit(X, y)
    np.testing.assert_allclose(c.fold_errors, errs, rtol=1e-8)
    assert c.cv_error == pytest.approx(np.mean(errs))
    np.testing.assert_allclose(c.coef, full.coef_, atol=1e-12)
    assert c.rss == pytest.approx(np.sum((y - X @ full.coef_[0]) ** 2), rel=1e-8)
    n, k = len(y), c.n_terms
    aic = n * np.log(c.rss / n) + 2 * k
    assert c.aicc == pytest.approx(aic + 2 * k * (k + 1) / (n - k - 1))
    assert c.bic == pytest.approx(n * np.log(c.rss / n) + k * np.log(n))
    # dedupe: one candidate per support, each the best cv_error of its support
    keys = [c.support.tobytes() for c in gs.candidates_]
    assert len(keys) == len(set(keys))
    for cc in gs.candidates_:
        same = [a.cv_error for a in gs.all_candidates_ if np.array_equal(a.support, cc.support)]
        assert cc.cv_error == min(same)
    assert gs.cv_error_grid_.shape == gs.n_terms_grid_.shape == (4, 2)


def test_grid_search_knee_and_ic_recover_true_support():
    X, y, xi, lo, hi = _problem(seed=3, n=3000)
    opt = BoxSR3(lower=lo, upper=hi, normalize_columns=True)
    gs = GridSearch(opt, default_threshold_grid(50.0), default_nu_grid(3)).fit(X, y)
    assert len(gs.candidates_) >= 2  # the grid reaches sparser models than the truth
    chosen = gs.candidates_[knee(gs.candidates_)]
    np.testing.assert_array_equal(chosen.support[0], xi != 0)
    np.testing.assert_array_equal(gs.candidates_[best_by_ic(gs.candidates_)].support[0],
                                  xi != 0)
    np.testing.assert_allclose(chosen.coef[0], xi, atol=2e-3)
    for c in gs.all_candidates_:  # the box holds everywhere
        assert np.all(c.coef[0] >= lo) and np.all(c.coef[0] <= hi)


def test_grid_search_bad_input():
    X, y, *_ = _problem(n=100)
    with pytest.raises(ValueError, match="nus"):
        GridSearch(BoxSR3(), [0.1], [0.0]).fit(X, y)
    with pytest.raises(ValueError, match="thresholds"):
        GridSearch(BoxSR3(), [-0.1], [1.0]).fit(X, y)
    with pytest.raises(ValueError, match="optimizer"):
        GridSearch(object(), [0.1], [1.0]).fit(X, y)
    with pytest.raises(ValueError, match="finite"):
        GridSearch(BoxSR3(), [0.1], [1.0]).fit(np.where(X > 2, np.nan, X), y)
