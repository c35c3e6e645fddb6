"""The joint Δf(z, V) fit (afmlearn/fm/fit.py) and the Kelvin parabolas on synthetic maps of a
known law: V_cpd recovered, the baseline without electrostatics worse, the profile interval
covers the truth, and the model's own vertex moves from V_cpd towards V_far."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.fm import FMFit, FMLaw, FMSpectroscopy, kelvin_parabolas, model_hz

CAL = {"spring_constant_n_per_m": 1800.0, "amplitude_m": 0.5e-9,
       "resonance_frequency_hz": 19796.5}
TRUE = FMLaw(hamaker_j=0.0, modulus_pa=0.0, tip_radius_m=5e-9, vcpd_v=1.75,
             es_radius_m=80e-9, es_setback_m=3e-9, far_gradient_n_per_m_v2=3e-3,
             far_vcpd_v=0.5, z_contact_m=-30.5e-9, offset_hz=-0.2)


def synthetic(noise_hz: float, seed: int = 0, n_z: int = 25, n_v: int = 17) -> FMSpectroscopy:
    z = -28e-9 + 0.8e-9 * np.arange(n_z)
    bias = np.linspace(10.0, -10.0, n_v)
    empty = FMSpectroscopy(np.zeros((n_z, n_v)), z, bias, **CAL)
    df = model_hz(empty, TRUE, n_nodes=128)
    df = df + np.random.default_rng(seed).normal(0.0, noise_hz, df.shape)
    return FMSpectroscopy(df, z, bias, **CAL)


def test_kelvin_parabola_vertex_of_an_exact_parabola():
    z = np.linspace(0, 2e-9, 4)
    bias = np.linspace(-3, 3, 13)
    vc = np.array([0.5, 0.7, -0.2, 1.1])
    df = -0.3 * (bias[None, :] - vc[:, None]) ** 2 + 2.0
    out = kelvin_parabolas(FMSpectroscopy(df, z, bias, **CAL))
    np.testing.assert_allclose(out["vcpd_v"], vc, atol=1e-10)
    np.testing.assert_allclose(out["vertex_hz"], 2.0, atol=1e-9)
    np.testing.assert_allclose(out["rms_hz"], 0.0, atol=1e-9)


def test_model_vertex_moves_from_the_apex_cpd_towards_the_far_field_cpd():
    spec = synthetic(0.0)
    v = kelvin_parabolas(spec)["vcpd_v"]
    assert TRUE.far_v < v[-1] < v[0] < TRUE.vcpd_v  # far rows closer to V_far


def test_joint_fit_recovers_vcpd_and_beats_the_baseline_on_a_noisy_map():
    spec = synthetic(1.0 / 6.0)
    fit = FMFit(contact_bounds_m=(-32e-9, -29e-9)).fit(spec)
    assert fit.law_.vcpd_v == pytest.approx(1.75, abs=0.05)
    assert fit.law_.far_v == pytest.approx(0.5, abs=0.5)
    assert fit.rms_hz_ == pytest.approx(1.0 / 6.0, rel=0.15)  # down to the noise
    base = FMFit(electrostatic=False, contact_bounds_m=(-32e-9, -29e-9)).fit(spec)
    assert base.rms_hz_ > 5 * fit.rms_hz_
    prof = fit.profile_vcpd(spec, half_width_v=0.1, n_points=7)
    assert prof["low_v"] is not None and prof["high_v"] is not None
    assert prof["low_v"] - 0.02 < 1.75 < prof["high_v"] + 0.02


def test_fit_of_a_noise_free_map_is_exact_in_the_linear_parameters():
    spec = synthetic(0.0, n_z=12, n_v=9)
    fit = FMFit(contact_bounds_m=(-32e-9, -29e-9), radius_starts_m=(5e-9,))
    fit.fit(spec, initial=TRUE)
    assert fit.rms_hz_ < 1e-3
    assert fit.law_.far_gradient_n_per_m_v2 == pytest.approx(3e-3, rel=1e-3)
    assert fit.law_.far_v == pytest.approx(0.5, abs=1e-3)
    assert fit.law_.offset_hz == pytest.approx(-0.2, abs=1e-3)


def test_bad_inputs_raise():
    spec = synthetic(0.0, n_z=5, n_v=3)
    with pytest.raises(ValueError, match="bias columns"):
        FMFit().fit(spec)
    with pytest.raises(ValueError, match="free V_cpd"):
        FMFit(vcpd_v=0.0).profile_vcpd(spec)
    with pytest.raises(ValueError, match="tip_radius_m"):
        FMLaw(hamaker_j=0.0, modulus_pa=0.0, tip_radius_m=0.0)
