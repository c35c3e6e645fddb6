"""Coupling score aggregation, sweet-spot interval, IoU, ROC AUC and the held-out metrics."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from afmlearn.qrnn.coupling import (
    CouplingFlag,
    directions,
    interval_iou,
    roc_auc,
    sweet_spot_interval,
    trace_scores,
)
from afmlearn.qrnn.evaluate import nrmse_per_period, valid_prediction_time


def test_trace_scores_are_group_means_and_flag_uses_the_threshold():
    scores = np.array([0.1, 0.3, 0.9, 0.7, 0.5])
    groups = np.array([4, 4, 1, 1, 7])
    ids, s = trace_scores(scores, groups)
    np.testing.assert_array_equal(ids, [1, 4, 7])
    np.testing.assert_allclose(s, [0.8, 0.2, 0.5])
    _, _, flags = CouplingFlag(threshold=0.5)(scores, groups)
    np.testing.assert_array_equal(flags, [True, False, True])
    with pytest.raises(ValueError, match="threshold"):
        CouplingFlag(threshold=1.0)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        trace_scores([0.2, 1.5], [0, 1])


def test_roc_auc_matches_the_pairwise_definition():
    rng = np.random.default_rng(3)
    y = rng.random(60) < 0.3
    s = np.round(rng.random(60) + 0.4 * y, 1)          # rounding makes ties
    pos, neg = s[y], s[~y]
    pairs = [1.0 if a > b else 0.5 if a == b else 0.0 for a, b in itertools.product(pos, neg)]
    assert roc_auc(y, s) == pytest.approx(np.mean(pairs), abs=1e-12)
    assert roc_auc([0, 0, 1, 1], [0.1, 0.2, 0.8, 0.9]) == 1.0
    assert roc_auc([0, 0, 1, 1], [0.9, 0.8, 0.2, 0.1]) == 0.0
    assert np.isnan(roc_auc([1, 1], [0.2, 0.3]))


def test_directions_split_forward_and_reverse_at_the_turning_point():
    f = np.linspace(1.0, 2.0, 5)
    both = np.concatenate([f, f[::-1]])                 # turning point repeated
    assert directions(both) == [slice(0, 5), slice(5, 10)]
    assert directions(np.concatenate([f, f[-2::-1]])) == [slice(0, 5), slice(5, 9)]
    assert directions(f) == [slice(0, 5)]
    assert directions([3.0]) == [slice(0, 1)]


def test_sweet_spot_interval_longest_run_and_iou():
    w = np.linspace(0.98, 1.03, 11)
    s = np.array([0, 0.6, 0, 0.7, 0.8, 0.9, 0.2, 0, 0.9, 0.95, 0])
    assert sweet_spot_interval(w, s) == (pytest.approx(w[3]), pytest.approx(w[5]))
    # order of the points does not matter
    perm = np.random.default_rng(0).permutation(w.size)
    assert sweet_spot_interval(w[perm], s[perm]) == sweet_spot_interval(w, s)
    assert sweet_spot_interval(w, np.zeros_like(w)) is None
    # IoU counts points: [3..5] vs [4..6] share 2 of 4 points
    assert interval_iou(w, (w[3], w[5]), (w[4], w[6])) == pytest.approx(0.5)
    assert interval_iou(w, None, None) == 1.0
    assert interval_iou(w, (w[0], w[1]), None) == 0.0


def test_nrmse_per_period_and_valid_prediction_time():
    p, horizon = 8, 3
    t = np.arange(horizon * p) / p
    true = np.sin(2 * np.pi * t)[None, :]
    err = np.repeat([0.0, 0.1, 0.5], p) * np.cos(7 * np.arange(horizon * p))
    pred = true + err[None, :]
    e = nrmse_per_period(pred, true, horizon=horizon)
    # reference: plain loop over periods, design.md section 4
    ref = [np.sqrt(np.mean((pred[0, k * p:(k + 1) * p] - true[0, k * p:(k + 1) * p]) ** 2))
           / np.ptp(true[0, k * p:(k + 1) * p]) for k in range(horizon)]
    np.testing.assert_allclose(e[0], ref)
    assert e[0, 0] == 0.0
    np.testing.assert_array_equal(valid_prediction_time(e, threshold=0.1), [2.0])
    np.testing.assert_array_equal(valid_prediction_time(np.zeros((2, 3))), [3.0, 3.0])
    np.testing.assert_array_equal(valid_prediction_time(np.full((1, 3), 0.2)), [0.0])
