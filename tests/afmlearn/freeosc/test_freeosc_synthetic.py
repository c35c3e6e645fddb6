"""simulate_free: the exact linear solution against a plain ODE integration and resonance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from afmlearn.freeosc import simulate_free


def test_linear_lever_matches_a_reference_ode_integration() -> None:
    """Plain reference: scipy's adaptive RK45 on x'' + x'/Q + x = f(tau), same forcing."""
    q, spp, n_periods, ac = 50.0, 19.0, 100, 0.2
    y, _ = simulate_free(n_periods=n_periods, samples_per_period=spp, quality_factor=q,
                         modulation_depth=0.1, modulation_periods=60.0, ac_force=ac,
                         ac_phase_rad=0.3)

    def rhs(tau, s):
        env = 1.0 + 0.1 * math.sin(tau / 60.0)
        f = env / q * math.sin(tau) + ac * math.cos(2 * tau + 0.3)
        return [s[1], f - s[1] / q - s[0]]

    tau = np.arange(y.size) * 2 * math.pi / spp
    ref = solve_ivp(rhs, (0, tau[-1]), [-1.0, 0.0], t_eval=tau, rtol=1e-9, atol=1e-11).y[0]
    # midpoint-held forcing on a grid 8x finer than the samples: error ~ dtau^2
    assert np.max(np.abs(y - ref)) < 3e-3


def test_resonant_amplitude_and_sampling() -> None:
    y, fs = simulate_free(n_periods=3000, modulation_depth=0.0, quality_factor=100.0)
    assert fs == pytest.approx(19.0)
    tail = y[-19 * 200 :]
    assert (tail.max() - tail.min()) / 2 == pytest.approx(1.0, abs=0.02)


def test_bad_settings_raise_naming_the_parameter() -> None:
    with pytest.raises(ValueError, match="n_periods"):
        simulate_free(n_periods=10)
    with pytest.raises(ValueError, match="modulation_periods"):
        simulate_free(quality_factor=1000.0, modulation_periods=100.0)
    with pytest.raises(ValueError, match="ac_force"):
        simulate_free(ac_force=-1.0)
