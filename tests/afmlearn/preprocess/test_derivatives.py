"""Savitzky-Golay, spectral and harmonic-fit derivatives on analytic signals."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.preprocess import (
    HarmonicDerivatives,
    SavitzkyGolay,
    Spectral,
    default_window,
    savgol_derivatives,
    spectral_derivatives,
)

OMEGA = 0.97


def test_savgol_is_exact_on_a_cubic():
    t = np.linspace(-2, 3, 301)
    x = 0.5 - t + 0.3 * t**2 - 0.2 * t**3
    xs, xd, xdd = savgol_derivatives(x, t[1] - t[0], window=21, order=3)
    np.testing.assert_allclose(xs, x, atol=1e-10)
    np.testing.assert_allclose(xd, -1 + 0.6 * t - 0.6 * t**2, atol=1e-9)
    np.testing.assert_allclose(xdd, 0.6 - 1.2 * t, atol=1e-8)


def test_savgol_sinusoid_error_matches_the_filter_bias():
    """A cubic SG filter of half-width h attenuates x'' of cos(w t) by ~ 1 - (w h)^2 * c."""
    spp = 200
    dt = 2 * np.pi / (OMEGA * spp)
    tau = np.arange(5 * spp) * dt
    x = np.cos(OMEGA * tau)
    _, xd, xdd = savgol_derivatives(x, dt, window=11, order=3)
    inner = slice(20, -20)
    np.testing.assert_allclose(xd[inner], -OMEGA * np.sin(OMEGA * tau[inner]), atol=1e-5)
    np.testing.assert_allclose(xdd[inner], -OMEGA**2 * x[inner], atol=5e-3)


def test_spectral_is_exact_on_whole_periods():
    n, periods = 512, 4
    dt = 2 * np.pi * periods / (OMEGA * n)
    tau = np.arange(n) * dt
    x = np.cos(OMEGA * tau) + 0.2 * np.sin(3 * OMEGA * tau)
    xs, xd, xdd = spectral_derivatives(x, dt)
    np.testing.assert_allclose(xs, x, atol=1e-12)
    np.testing.assert_allclose(xd, -OMEGA * np.sin(OMEGA * tau)
                               + 0.6 * OMEGA * np.cos(3 * OMEGA * tau), atol=1e-11)
    np.testing.assert_allclose(xdd, -OMEGA**2 * np.cos(OMEGA * tau)
                               - 1.8 * OMEGA**2 * np.sin(3 * OMEGA * tau), atol=1e-11)
    low = spectral_derivatives(x, dt, cutoff=2 * OMEGA)[0]
    np.testing.assert_allclose(low, np.cos(OMEGA * tau), atol=1e-12)


def test_estimator_objects_agree():
    spp = 100
    dt = 2 * np.pi / (OMEGA * spp)
    tau = np.arange(int(7.5 * spp)) * dt  # 7.5 periods: Spectral uses the first 7
    x = np.cos(OMEGA * tau) + 0.1 * np.cos(2 * OMEGA * tau)
    exact = -OMEGA**2 * np.cos(OMEGA * tau) - 0.4 * OMEGA**2 * np.cos(2 * OMEGA * tau)
    sg = SavitzkyGolay()(tau, x, omega=OMEGA)
    w = default_window(spp)
    np.testing.assert_array_equal(sg[2], savgol_derivatives(x, dt, window=w)[2])
    sp = Spectral()(tau, x, omega=OMEGA)
    assert np.all(np.isnan(sp[2][7 * spp:]))
    np.testing.assert_allclose(sp[2][: 7 * spp], exact[: 7 * spp], atol=1e-10)
    hd = HarmonicDerivatives()(tau, x, omega=OMEGA)
    np.testing.assert_allclose(hd[2], exact, atol=1e-10)


def test_default_window():
    assert default_window(200) == 31
    assert default_window(1500) == 225
    assert default_window(20) == 5  # at least order + 2, odd
    assert default_window(1000, fraction=0.05) == 51


def test_bad_input():
    x = np.zeros(50)
    with pytest.raises(ValueError, match="window"):
        savgol_derivatives(x, 0.1, window=10)
    with pytest.raises(ValueError, match="window"):
        savgol_derivatives(x, 0.1, window=51)
    with pytest.raises(ValueError, match="dt"):
        savgol_derivatives(x, 0.0, window=11)
    with pytest.raises(ValueError, match="samples_per_period"):
        default_window(0)
    with pytest.raises(ValueError, match="cutoff"):
        spectral_derivatives(x, 0.1, cutoff=-1.0)
