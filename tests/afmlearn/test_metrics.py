"""Metrics of design.md section 4 on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.metrics import (
    accuracy,
    coefficient_errors,
    force_accuracy,
    nrmse,
    r2,
    valid_prediction_time,
)


def test_nrmse_accuracy_r2_by_hand():
    true = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    pred = true + np.array([0.1, -0.1, 0.1, -0.1, 0.1])
    assert nrmse(pred, true) == pytest.approx(0.1 / 4)
    assert accuracy(pred, true) == pytest.approx(1 - 0.1 / 4)
    assert r2(pred, true) == pytest.approx(1 - 0.05 / 10)
    assert nrmse(pred, true, scale=2.0) == pytest.approx(0.05)
    assert nrmse(true, true) == 0.0 and r2(true, true) == 1.0
    # NaN pairs are ignored
    assert nrmse(np.r_[pred, np.nan], np.r_[true, 7.0]) == pytest.approx(0.025)
    assert math.isnan(r2(np.ones(3), np.full(3, 2.0)))
    assert nrmse(np.ones(3), np.full(3, 2.0)) == math.inf
    with pytest.raises(ValueError, match="shape"):
        nrmse(np.ones(3), np.ones(4))


def test_force_accuracy_regions_use_the_whole_range():
    a0 = 0.1
    z = np.array([0.05, 0.09, 0.1, 0.11, 0.2, 0.5, 1.0, 0.098])
    true = np.array([5.0, 1.0, -1.0, -0.9, -0.3, -0.05, 0.0, 0.5])  # range 6
    err = np.array([0.6, 0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0])
    out = force_accuracy(true + err, true, z, a0, w=0.02)
    assert out["repulsive"]["n"] == 4  # z <= 0.1
    assert out["attractive"]["n"] == 3  # z > 0.12
    assert out["near_a0"]["n"] == 4  # 0.09, 0.1, 0.11, 0.098
    assert out["whole"]["n"] == 8
    assert out["repulsive"]["nrmse"] == pytest.approx(math.sqrt(0.36 / 4) / 6)
    assert out["attractive"]["nrmse"] == pytest.approx(math.sqrt(0.09 / 3) / 6)
    assert out["near_a0"]["accuracy"] == 1.0
    assert out["whole"]["accuracy"] == pytest.approx(1 - math.sqrt(0.45 / 8) / 6)
    # the default band is 25 % of a0; NaN predictions are left out
    default = force_accuracy(np.r_[np.nan, true[1:]], true, z, a0)
    assert default["near_a0"]["n"] == 4 and default["repulsive"]["n"] == 3
    empty = force_accuracy(true, true, z + 10, a0)
    assert empty["repulsive"]["n"] == 0 and math.isnan(empty["repulsive"]["nrmse"])
    with pytest.raises(ValueError, match="a0"):
        force_accuracy(true, true, z, 0.0)


def test_valid_prediction_time():
    assert valid_prediction_time([0.01, 0.05, 0.2, 0.01]) == 2
    assert valid_prediction_time([0.01, 0.05]) == 2
    assert valid_prediction_time([0.01, np.nan, 0.0]) == 1
    assert valid_prediction_time([0.3, 0.05], threshold=0.5) == 2
    with pytest.raises(ValueError, match="threshold"):
        valid_prediction_time([0.1], threshold=0)


def test_coefficient_errors():
    est = {"x": -1.01, "x'": -0.002, "delta^1.5": 9.0, "z^-3": 0.1}
    true = {"x": -1.0, "x'": -0.002, "delta^1.5": 10.0, "z^-2": -0.5}
    out = coefficient_errors(est, true)
    assert out["terms"]["x"]["rel_error"] == pytest.approx(0.01)
    assert out["terms"]["delta^1.5"]["abs_error"] == pytest.approx(1.0)
    assert out["max_rel_error"] == pytest.approx(1.0)  # z^-2 missed entirely
    assert out["mean_rel_error"] == pytest.approx((0.01 + 0 + 0.1 + 1.0) / 4)
    assert out["missing"] == ["z^-2"] and out["spurious"] == ["z^-3"]
    assert not out["support_exact"]
    assert coefficient_errors(true, true)["support_exact"]
