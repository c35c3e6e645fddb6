"""Constraint-keeping moving-block bagging."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.identify.bagging import ConstrainedBagging, block_bootstrap_weights
from afmlearn.identify.optimizers import BoxSR3


def test_block_weights_are_whole_contiguous_blocks():
    rng = np.random.default_rng(0)
    w = block_bootstrap_weights(100, 7, 15, rng)
    assert w.sum() == 7 * 15 and np.all(w >= 0)
    # plain reference: the same 15 starts, each adding a window of 7 consecutive rows
    starts = np.random.default_rng(0).integers(0, 100 - 7 + 1, size=15)
    ref = np.zeros(100)
    for a in starts:
        ref[a:a + 7] += 1
    np.testing.assert_array_equal(w, ref)
    w2 = block_bootstrap_weights(100, 7, 15, np.random.default_rng(0))
    np.testing.assert_array_equal(w, w2)


def test_every_model_respects_box_and_equality():
    rng = np.random.default_rng(1)
    n, p, T = 600, 6, 2
    X = rng.normal(size=(n, p))
    xi = np.array([[1.3, -0.5, 0.0, 0.8, 0.0, 0.0], [0.0, 0.7, 0.0, 0.0, -0.4, 0.1]])
    Y = X @ xi.T + 0.3 * rng.normal(size=(n, T))
    lo = np.full((T, p), -np.inf)
    hi = np.full((T, p), np.inf)
    lo[0, 0], hi[0, 0] = 0.85, 1.15
    hi[0, 3] = 0.75
    C = np.zeros((1, T * p))
    C[0, 1], C[0, p + 1] = 1.0, 1.0  # coef(t0, f1) + coef(t1, f1) = 0.2
    opt = BoxSR3(0.15, 0.5, lower=lo, upper=hi, constraint_lhs=C, constraint_rhs=[0.2])
    bag = ConstrainedBagging(opt, n_models=30, block_size=20, seed=3).fit(X, Y)
    S = bag.coef_samples_
    assert S.shape == (30, T, p)
    assert np.all(S >= lo - 1e-12) and np.all(S <= hi + 1e-12)
    np.testing.assert_allclose(S.reshape(30, -1) @ C[0], 0.2, atol=1e-9)
    assert np.all(bag.coef_lo_ <= bag.coef_median_) and np.all(bag.coef_median_ <= bag.coef_hi_)
    assert np.all(bag.coef_median_ >= lo) and np.all(bag.coef_median_ <= hi)
    # the samples differ (it is a bootstrap) and the seed reproduces them
    assert np.ptp(S[:, 1, 1]) > 0
    again = ConstrainedBagging(opt, n_models=30, block_size=20, seed=3).fit(X, Y)
    np.testing.assert_array_equal(again.coef_samples_, S)


def test_fixed_support_spread_matches_ols_standard_error():
    """iid rows, block_size 1, fixed support: bootstrap std ~ sigma sqrt(diag((X^T X)^-1))."""
    rng = np.random.default_rng(2)
    n, p, sigma = 2000, 4, 0.5
    X = rng.normal(size=(n, p))
    xi = np.array([1.0, -2.0, 0.5, 0.0])
    y = X @ xi + sigma * rng.normal(size=n)
    bag = ConstrainedBagging(BoxSR3(0.2, 1.0), n_models=200, block_size=1, seed=0,
                             fixed_support=True).fit(X, y)
    se = sigma * np.sqrt(np.diag(np.linalg.inv(X.T @ X)))[:3]
    std = bag.coef_samples_[:, 0, :3].std(axis=0)
    np.testing.assert_allclose(std, se, rtol=0.2)
    assert np.all(bag.coef_samples_[:, 0, 3] == 0)
    assert np.all((bag.coef_lo_[0, :3] <= xi[:3]) & (xi[:3] <= bag.coef_hi_[0, :3]))


def test_inclusion_probability():
    rng = np.random.default_rng(4)
    n, p = 1500, 6
    X = rng.normal(size=(n, p))
    y = X @ np.array([1.0, 0.0, -0.6, 0.0, 0.0, 0.0]) + 0.2 * rng.normal(size=n)
    bag = ConstrainedBagging(BoxSR3(0.1, 1.0), n_models=40, block_size=50).fit(X, y)
    inc = bag.inclusion_probability_[0]
    assert inc[0] == 1.0 and inc[2] == 1.0
    assert np.all(inc[[1, 3, 4, 5]] <= 0.1)
    assert bag.block_size_ == 50


@pytest.mark.parametrize(("kwargs", "match"), [
    (dict(n_models=1), "n_models"),
    (dict(fraction=0.0), "fraction"),
    (dict(fraction=1.5), "fraction"),
    (dict(block_size=0), "block_size"),
    (dict(block_size=10_000), "block_size"),
])
def test_bad_settings(kwargs, match):
    X = np.random.default_rng(0).normal(size=(50, 3))
    with pytest.raises(ValueError, match=match):
        ConstrainedBagging(BoxSR3(), **kwargs).fit(X, X[:, 0])
    with pytest.raises(ValueError, match="optimizer"):
        ConstrainedBagging(object()).fit(X, X[:, 0])
