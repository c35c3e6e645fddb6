"""CalibrationConstraints.prior_gram: the calibration priors as Gram additions."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.identify.constraints import CalibrationConstraints


@pytest.mark.parametrize("source, drive_rel", [("free_deflection", 0.01),
                                               ("free_amplitude", 0.03), ("none", None)])
def test_prior_gram_is_a_gaussian_about_the_calibration(source, drive_rel):
    """Alone, the prior's normal equations return the calibrated values (-1/Q, -1, F_c), each
    weighted by noise variance / (relative width x value)^2; other coefficients are free."""
    cons = CalibrationConstraints()
    q, fc, s2, p = 250.0, 0.02, 3e-6, 6
    G0, b0 = cons.prior_gram(p, quality_factor=q, drive_amplitude=fc, drive_source=source,
                             noise_variance=s2, drive_index=2)
    mu = np.array([-1.0 / q, -1.0, fc])
    rel = np.array([0.05, 2e-3, np.nan if drive_rel is None else drive_rel])
    expected = s2 / (rel * np.abs(mu)) ** 2
    has = np.isfinite(expected)
    np.testing.assert_allclose(np.diag(G0)[:3][has], expected[has], rtol=1e-12)
    assert np.count_nonzero(G0) == has.sum() and np.all(G0[3:] == 0)
    np.testing.assert_allclose(b0[:3][has] / np.diag(G0)[:3][has], mu[has], rtol=1e-12)
    # no drive amplitude: no drive prior whatever the source
    G1, _ = cons.prior_gram(p, quality_factor=q, drive_amplitude=None, drive_source=source,
                            noise_variance=s2)
    assert G1[2, 2] == 0 and G1[0, 0] == G0[0, 0]


def test_lever_boxes_hold_the_calibration_within_the_tolerances():
    """-1/Q, -1 and F_c inside their boxes of the stated relative half-widths; the rest free."""
    cons = CalibrationConstraints(tolerance=0.15, stiffness_tolerance=0.05)
    q, fc, p = 200.0, 0.03, 7
    lo, hi = cons.lever_boxes(p, quality_factor=q, drive_amplitude=fc, drive_index=3)
    mu = np.array([-1.0 / q, -1.0, np.nan, fc])
    for k, tol in ((0, 0.15), (1, 0.05), (3, 0.15)):
        assert lo[k] < mu[k] < hi[k]
        np.testing.assert_allclose((hi[k] - lo[k]) / 2, tol * abs(mu[k]), rtol=1e-12)
    free = [2, 4, 5, 6]
    assert np.all(np.isneginf(lo[free])) and np.all(np.isposinf(hi[free]))
    lo2, hi2 = cons.lever_boxes(p, quality_factor=q, drive_amplitude=None, drive_index=3)
    assert np.isneginf(lo2[3]) and np.isposinf(hi2[3]) and lo2[1] == lo[1]
