"""Giessibl's finite-amplitude Δf (afmlearn/fm/forward.py): quadrature vs a plain reference,
the small-amplitude limit, the sign convention and the force-law evaluator vs NumPy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from afmlearn.fm.forward import frequency_shift, law_force, law_frequency_shift
from simulator.forces.law import ForceLaw, Kind, Term

LAW = ForceLaw((Term(Kind.SPHERE_VDW, -0.02, 3.0), Term(Kind.INDENTATION, 5.0, 1.5),
                Term(Kind.SPHERE_ELECTROSTATIC, -0.01, 20.0)), a0=0.3, has_contact=True)


def reference_force(d):
    """Plain NumPy form of LAW (physics.md section 3; held at a0 in contact)."""
    d = np.asarray(d, float)
    zz = np.maximum(d, 0.3)
    out = -0.02 / (zz**2 * (zz + 6.0) ** 2) - 0.01 / (zz * (zz + 20.0))
    return out + np.where(d <= 0.3, 5.0 * np.abs(0.3 - d) ** 1.5, 0.0)


def test_compiled_law_force_matches_the_numpy_reference():
    d = np.linspace(-0.5, 10.0, 301)
    np.testing.assert_allclose(law_force(LAW, d), reference_force(d), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("amplitude", [0.2, 2.0])
def test_chebyshev_quadrature_matches_adaptive_integration_over_the_cycle(amplitude):
    # Omega = -(1/(pi A)) int_0^pi F(d + A (1 + cos th)) cos th dth  (plain, adaptive)
    for d in (0.0, 0.5, 3.0):
        ref = -quad(lambda th, d=d: reference_force(d + amplitude * (1 + np.cos(th)))
                    * np.cos(th), 0.0, np.pi, limit=400)[0] / (np.pi * amplitude)
        got = law_frequency_shift(LAW, [d], amplitude=amplitude, n_nodes=512)[0]
        assert got == pytest.approx(ref, rel=2e-3, abs=1e-9)


def test_small_amplitude_limit_is_minus_half_the_force_gradient():
    d = np.linspace(1.0, 5.0, 9)
    a = 1e-4
    om = law_frequency_shift(LAW, d - a, amplitude=a)  # centre of the orbit at d
    grad = (reference_force(d + 1e-6) - reference_force(d - 1e-6)) / 2e-6
    np.testing.assert_allclose(om, -grad / 2.0, rtol=1e-3)


def test_linear_force_gives_the_exact_constant_shift_at_any_amplitude():
    # F = g d (constant gradient g): Omega = -g / 2 exactly, for every amplitude
    for a in (0.01, 1.0, 50.0):
        om = frequency_shift(lambda d: 0.3 * d, np.array([0.0, 2.0]), amplitude=a, n_nodes=8)
        np.testing.assert_allclose(om, -0.15, rtol=1e-12)


def test_repulsion_raises_and_attraction_lowers_the_frequency():
    rep = frequency_shift(lambda d: np.exp(-d), [0.5], amplitude=1.0)[0]
    att = frequency_shift(lambda d: -np.exp(-d), [0.5], amplitude=1.0)[0]
    assert rep > 0 > att


def test_bad_settings_raise():
    with pytest.raises(ValueError, match="amplitude"):
        frequency_shift(np.exp, [1.0], amplitude=0.0)
    with pytest.raises(ValueError, match="n_nodes"):
        frequency_shift(np.exp, [1.0], amplitude=1.0, n_nodes=1)
