"""fit_harmonics / HarmonicFit / phase_average: against a dense least-squares reference, analytic
signals, and the simulator's own velocity and equation of motion."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.io import read_trace
from afmlearn.preprocess import calibrate, fit_harmonics, phase_average

OMEGA = 1.03
SPP = 200


def _signal(tau, omega=OMEGA):
    """0.2 + cos(W t) + 0.3 sin(2 W t + 0.4) + 0.01 cos(7 W t), and its two derivatives."""
    w = omega
    x = 0.2 + np.cos(w * tau) + 0.3 * np.sin(2 * w * tau + 0.4) + 0.01 * np.cos(7 * w * tau)
    xd = (-w * np.sin(w * tau) + 0.6 * w * np.cos(2 * w * tau + 0.4)
          - 0.07 * w * np.sin(7 * w * tau))
    xdd = (-w**2 * np.cos(w * tau) - 1.2 * w**2 * np.sin(2 * w * tau + 0.4)
           - 0.49 * w**2 * np.cos(7 * w * tau))
    return x, xd, xdd


def _tau(n, spp=SPP, omega=OMEGA, t0=0.0):
    return t0 + np.arange(n) * 2 * np.pi / (omega * spp)


def test_matches_dense_least_squares_on_irregular_samples():
    rng = np.random.default_rng(1)
    tau = np.sort(rng.uniform(0, 40, 900))
    x = _signal(tau)[0] + 0.05 * rng.standard_normal(tau.size)
    fit = fit_harmonics(tau, x, OMEGA, n_harmonics=9)
    k = np.arange(1, 10)
    design = np.column_stack([np.ones_like(tau), np.cos(np.outer(tau, k) * OMEGA),
                              np.sin(np.outer(tau, k) * OMEGA)])
    ref, *_ = np.linalg.lstsq(design, x, rcond=None)
    np.testing.assert_allclose(fit.coefficients, ref, atol=1e-10)
    resid = x - design @ ref
    assert fit.residual_rms == pytest.approx(np.sqrt(np.mean(resid**2)), rel=1e-9)
    np.testing.assert_allclose(fit.evaluate(tau), design @ ref, atol=1e-10)


def test_exact_signal_and_analytic_derivatives():
    tau = _tau(3000, t0=0.7)
    x, xd, xdd = _signal(tau)
    fit = fit_harmonics(tau, x, OMEGA, n_harmonics=10)
    np.testing.assert_allclose(fit.evaluate(tau), x, atol=1e-11)
    np.testing.assert_allclose(fit.evaluate(tau, 1), xd, atol=1e-10)
    np.testing.assert_allclose(fit.evaluate(tau, 2), xdd, atol=1e-9)
    amps = fit.amplitudes
    np.testing.assert_allclose(amps[[0, 1, 6]], [1.0, 0.3, 0.01], atol=1e-12)
    assert np.all(np.delete(amps, [0, 1, 6]) < 1e-12)


def test_auto_order_stops_at_the_noise_floor_and_averages_noise():
    rng = np.random.default_rng(2)
    tau = _tau(100 * SPP)
    x, xd, _ = _signal(tau)
    sigma = 0.01
    fit = fit_harmonics(tau, x + sigma * rng.standard_normal(tau.size), OMEGA)
    # harmonic 7 (amplitude 0.01) is far above the floor sqrt(2/n) sigma ~ 1e-4; 8+ are noise
    assert fit.n_harmonics == 7
    assert fit.noise_rms == pytest.approx(sigma, rel=0.02)
    assert fit.is_periodic
    # averaging over 100 periods: error of the denoised orbit well below the noise
    assert np.sqrt(np.mean((fit.evaluate(tau) - x) ** 2)) < 0.1 * sigma
    # each coefficient has std sigma sqrt(2/n), so the x' error has RMS
    # sigma sqrt(2/n) W sqrt(sum k^2) / sqrt(2)
    expected = sigma * np.sqrt(1 / tau.size) * OMEGA * np.sqrt(np.sum(np.arange(1, 8) ** 2))
    err = np.sqrt(np.mean((fit.evaluate(tau, 1) - xd) ** 2))
    assert 0.5 * expected < err < 2 * expected


def test_is_periodic_flags_drift_and_a_second_frequency():
    rng = np.random.default_rng(3)
    tau = _tau(50 * SPP)
    x = _signal(tau)[0] + 0.01 * rng.standard_normal(tau.size)
    assert fit_harmonics(tau, x, OMEGA).is_periodic
    drift = x + 0.01 * tau / tau[-1]
    assert not fit_harmonics(tau, drift, OMEGA).is_periodic
    beat = x + 0.02 * np.cos(0.9 * OMEGA * tau)
    assert not fit_harmonics(tau, beat, OMEGA).is_periodic


def test_subharmonic_period_multiple():
    tau = _tau(20 * SPP)
    x = np.cos(OMEGA * tau) + 0.2 * np.cos(0.5 * OMEGA * tau + 1.0)
    sub = fit_harmonics(tau, x, OMEGA, n_harmonics=4, period_multiple=2)
    assert sub.residual_rms < 1e-10
    np.testing.assert_allclose(sub.amplitudes[:2], [0.2, 1.0], atol=1e-10)
    assert fit_harmonics(tau, x, OMEGA, n_harmonics=4).residual_rms > 0.1


def test_phase_average_recovers_the_waveform_and_noise():
    rng = np.random.default_rng(4)
    tau = _tau(400 * 64, spp=64, t0=np.pi / (64 * OMEGA))  # one sample per bin centre
    x = np.cos(OMEGA * tau)
    bins, mean, std = phase_average(tau, x + 0.05 * rng.standard_normal(tau.size), OMEGA, 64)
    np.testing.assert_allclose(mean, np.cos(bins), atol=0.01)
    np.testing.assert_allclose(std, 0.05, rtol=0.15)


def test_bad_input():
    tau = _tau(1000)
    x = _signal(tau)[0]
    with pytest.raises(ValueError, match="omega"):
        fit_harmonics(tau, x, 0.0)
    with pytest.raises(ValueError, match="n_harmonics"):
        fit_harmonics(tau, x, OMEGA, n_harmonics=SPP)  # above Nyquist
    with pytest.raises(ValueError, match="period_multiple"):
        fit_harmonics(tau, x, OMEGA, period_multiple=0)
    with pytest.raises(ValueError, match="finite"):
        fit_harmonics(tau, np.where(tau > 3, np.nan, x), OMEGA)
    with pytest.raises(ValueError, match="derivative"):
        fit_harmonics(tau, x, OMEGA, n_harmonics=3).evaluate(tau, 3)


def test_derivatives_of_a_simulated_orbit_match_the_simulator(noiseless_tapping):
    """x' against the integrator's recorded velocity; x'' against the equation of motion
    x'' = -x'/Q - x - F_ts + B cos(theta) evaluated with the true force and drive."""
    path, obj = noiseless_tapping
    res = obj["result"]
    cal = calibrate(read_trace(path))
    fit = fit_harmonics(cal.tau, cal.x, cal.omega)
    velocity = res.velocity.sum(axis=-2)
    b = obj["excitation"].amplitude
    xdd = -velocity / cal.quality_factor - res.deflection - res.force + b * np.cos(res.phase)
    assert fit.n_harmonics > 50  # the contact needs many harmonics
    assert fit.residual_rms < 1e-6
    np.testing.assert_allclose(fit.evaluate(cal.tau), res.deflection, atol=1e-6)
    assert np.max(np.abs(fit.evaluate(cal.tau, 1) - velocity)) < 1e-4 * np.ptp(velocity)
    err = fit.evaluate(cal.tau, 2) - xdd
    assert np.max(np.abs(err)) < 2e-3 * np.ptp(xdd)
    assert np.sqrt(np.mean(err**2)) < 2e-4 * np.ptp(xdd)
