"""Lock-in demodulator and the lock-in curve scenario: known sinusoids, the filter against a
plain loop, the analytic step response and bandwidth, and a free lever's curve."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulator import RK4, Cantilever, System, TipExcitation
from simulator.forces import NoInteraction
from simulator.lockin import LockIn
from simulator.scenarios.lockin import LockInCurve


def plain_filter(x, *, dt, tau_c, order, start):
    """Reference: cascaded RC sections, one sample at a time (exact for a held input)."""
    alpha = 1.0 - math.exp(-dt / tau_c)
    y = np.array(x, dtype=float)
    for _ in range(order):
        state = start
        out = np.empty_like(y)
        for k, v in enumerate(y):
            state = state + alpha * (v - state)
            out[k] = state
        y = out
    return y


@pytest.mark.parametrize("order", [1, 2, 4])
def test_filter_matches_plain_loop(order):
    rng = np.random.default_rng(order)
    x = rng.standard_normal(3000)
    li = LockIn(bandwidth=0.02, order=order, output_interval=1.0)
    got = li.filter(x, dt=0.1, initial=0.3)
    ref = plain_filter(x, dt=0.1, tau_c=li.time_constant, order=order, start=0.3)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("order", [1, 3, 4])
def test_step_response_is_the_erlang_law(order):
    li = LockIn(bandwidth=0.01, order=order, output_interval=1.0)
    dt = li.time_constant / 2000.0
    t = dt * np.arange(1, 20 * 2000 * order // order + 1)
    y = li.filter(np.ones_like(t), dt=dt, initial=0.0)
    np.testing.assert_allclose(y, li.step_response(t), atol=2e-3)
    # 63 % point of a single section is its time constant
    if order == 1:
        assert abs(t[np.searchsorted(y, 1.0 - math.exp(-1.0))] - li.time_constant) \
            < 2e-3 * li.time_constant


@pytest.mark.parametrize("order", [1, 4])
def test_minus_3db_at_the_bandwidth(order):
    li = LockIn(bandwidth=0.01, order=order, output_interval=1.0)
    dt = 0.05
    t = dt * np.arange(400_000)
    y = li.filter(np.cos(2 * np.pi * li.bandwidth * t), dt=dt, initial=0.0)
    tail = y[t > 10 * order * li.time_constant + 300]
    gain = np.sqrt(2.0 * np.mean(tail**2))
    assert gain == pytest.approx(1.0 / math.sqrt(2.0), rel=5e-3)


@pytest.mark.parametrize("amp,phi", [(1.3, math.pi / 2), (0.2, 2.5), (2.0, 0.3)])
def test_known_sinusoid(amp, phi):
    dt = 2 * np.pi / 50
    theta = 0.7 + dt * np.arange(60_000)
    x = amp * np.cos(theta - phi) + 0.1  # plus a static deflection, rejected by the mixer
    li = LockIn(bandwidth=0.005, order=4, output_interval=20 * np.pi)
    out = li.demodulate(x, theta, dt=dt)
    late = out.tau > 30 * li.time_constant
    np.testing.assert_allclose(out.amplitude[late], amp, rtol=2e-3)
    np.testing.assert_allclose(out.phase[late], phi, atol=2e-3)
    np.testing.assert_allclose(np.diff(out.tau), 20 * np.pi, rtol=1e-12)


def test_bad_settings_raise():
    with pytest.raises(ValueError, match="bandwidth"):
        LockIn(bandwidth=0.0, output_interval=1.0)
    with pytest.raises(ValueError, match="order"):
        LockIn(bandwidth=0.01, order=9, output_interval=1.0)
    with pytest.raises(ValueError, match="output_interval"):
        LockIn(bandwidth=0.01, output_interval=-1.0)
    with pytest.raises(ValueError, match="lockin"):
        LockInCurve(lockin="fast")


def test_free_lever_curve_reads_free_amplitude_and_quarter_lag():
    cl = Cantilever.rectangular(n_modes=1, quality_factor=50.0)
    system = System(cl, NoInteraction(), TipExcitation.for_free_amplitude(cl, 1.0, 0.5))
    li = LockIn(bandwidth=0.01, order=4, output_interval=10 * 2 * np.pi)
    scen = LockInCurve(gap_start=2.0, gap_end=1.0, n_periods=200, lockin=li,
                       samples_per_period=40, integrator=RK4(steps_per_period=80))
    rec = scen.run(system).meta["curve"]
    np.testing.assert_allclose(rec.amplitude, 0.5, rtol=2e-3)
    np.testing.assert_allclose(rec.phase, np.pi / 2, atol=3e-3)
    assert set(np.unique(rec.segment)) == {0, 1}
    assert rec.z_piezo.min() == pytest.approx(1.0, abs=0.06)
    assert np.all(np.diff(rec.z_piezo[rec.segment == 0]) < 0)
    assert np.all(np.diff(rec.z_piezo[rec.segment == 1]) > 0)
    np.testing.assert_allclose(rec.rest_gap, rec.z_piezo, atol=1e-9)  # no drift


def test_noise_and_drift_are_as_stated():
    cl = Cantilever.rectangular(n_modes=1, quality_factor=50.0)
    system = System(cl, NoInteraction(), TipExcitation.for_free_amplitude(cl, 1.0, 0.5))
    li = LockIn(bandwidth=0.01, order=4, output_interval=2 * np.pi)
    scen = LockInCurve(gap_start=2.0, gap_end=1.0, n_periods=400, lockin=li,
                       amplitude_noise=0.01, phase_noise=math.radians(0.5), drift=1e-4,
                       seed=3, samples_per_period=40, integrator=RK4(steps_per_period=80))
    rec = scen.run(system).meta["curve"]
    assert np.std(rec.amplitude) == pytest.approx(0.005, rel=0.15)
    assert np.std(rec.phase) == pytest.approx(math.radians(0.5), rel=0.15)
    np.testing.assert_allclose(rec.rest_gap - rec.z_piezo, 1e-4 * rec.tau, atol=1e-6)
