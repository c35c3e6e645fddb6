"""Measurement chain stages."""

import numpy as np
import pytest

from simulator.sensor import (
    DetectorNonlinearity,
    GaussianNoise,
    LowPass,
    Quantizer,
    SensorChain,
)


def sine(n=20000, spp=200):
    th = 2 * np.pi * np.arange(n) / spp
    return np.sin(th), 2 * np.pi / spp


def test_noise_level_is_relative_to_reference_and_seeded():
    x, dt = sine()
    y1 = SensorChain.default(noise_level=0.01, seed=3)(x, x_ref=2.0, dt=dt)
    y2 = SensorChain.default(noise_level=0.01, seed=3)(x, x_ref=2.0, dt=dt)
    np.testing.assert_array_equal(y1, y2)
    assert np.std(y1 - x) == pytest.approx(0.02, rel=0.03)


def test_lowpass_attenuates_above_cutoff_only():
    n, spp = 40000, 200
    th = 2 * np.pi * np.arange(n) / spp
    dt = 2 * np.pi / spp
    low, high = np.sin(th), np.sin(20 * th)
    lp = LowPass(cutoff=3.0, order=4)
    rng = np.random.default_rng(0)
    yl = lp.apply(low, x_ref=1, dt=dt, rng=rng)[n // 2:]
    yh = lp.apply(high, x_ref=1, dt=dt, rng=rng)[n // 2:]
    assert np.ptp(yl) / 2 == pytest.approx(1.0, abs=0.02)
    assert np.ptp(yh) / 2 < 1e-3
    with pytest.raises(ValueError, match="cutoff"):
        LowPass(cutoff=500.0).apply(low, x_ref=1, dt=dt, rng=rng)


def test_quantizer_step_and_clipping():
    q = Quantizer(bits=8, full_scale=1.0)
    x = np.linspace(-2, 2, 1001)
    y = q.apply(x, x_ref=1.0, dt=0.1, rng=None)
    lsb = 2.0 / 256
    assert np.max(np.abs(y[np.abs(x) < 0.99] - x[np.abs(x) < 0.99])) <= lsb / 2 + 1e-12
    assert y.max() < 1.0 and y.min() >= -1.0
    assert np.unique(np.round(y / lsb, 6)).size <= 256


def test_quadratic_nonlinearity_creates_second_harmonic_and_offset():
    x, dt = sine()
    y = DetectorNonlinearity(a2=0.1).apply(x, x_ref=1.0, dt=dt, rng=None)
    spec = np.abs(np.fft.rfft(y)) / x.size * 2
    k1 = x.size // 200
    assert spec[2 * k1] == pytest.approx(0.05, rel=1e-3)  # a2/2 at 2f
    assert np.mean(y) == pytest.approx(0.05, rel=1e-3)  # a2/2 offset


@pytest.mark.parametrize(
    ("factory", "name"),
    [
        (lambda: GaussianNoise(level=-0.1), "level"),
        (lambda: LowPass(cutoff=0.0), "cutoff"),
        (lambda: Quantizer(bits=1), "bits"),
        (lambda: DetectorNonlinearity(a2=3.0), "a2"),
        (lambda: SensorChain(["noise"]), "stages"),
    ],
)
def test_bad_parameters(factory, name):
    with pytest.raises(ValueError, match=name):
        factory()
