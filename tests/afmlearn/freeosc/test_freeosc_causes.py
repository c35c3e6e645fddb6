"""Cause models: nested in the baseline, coefficients recovered on known maps and forces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.freeosc import demodulate
from afmlearn.freeosc.causes import (
    AcBiasDrive,
    DetectorNonlinearity,
    DuffingStiffness,
    GapModulatedForce,
    HigherMode,
    LinearLever,
    Quantisation,
    transfer,
)
from afmlearn.freeosc.combined import Combined

FS = 19.0


@pytest.fixture(scope="module")
def fundamental():
    n = 40_000
    t = np.arange(n) / FS
    amp = 1.0 + 0.2 * np.sin(2 * math.pi * t / 1700)
    phase = 2 * math.pi * t + 0.7
    return amp * np.cos(phase), amp, phase


def _fit(cause, y):
    d = demodulate(y, sample_rate_hz=FS)
    v = np.flatnonzero(d.valid)
    cause.fit(y[v], d.take(v))
    return cause, d, v


ALL = [DetectorNonlinearity(), AcBiasDrive(), GapModulatedForce(), DuffingStiffness(),
       HigherMode(frequency_hz=6.27), Quantisation(step=0.01)]


@pytest.mark.parametrize("cause", ALL, ids=lambda c: type(c).__name__)
def test_every_cause_nests_the_baseline(cause, fundamental) -> None:
    """On a pure sinusoid every cause's extra coefficients vanish and it predicts the baseline."""
    x, _, _ = fundamental
    y = x + 0.05
    fitted, d, v = _fit(cause, y)
    base, _, _ = _fit(LinearLever(), y)
    pred = fitted.predict(d.take(v))
    assert np.max(np.abs(pred - base.predict(d.take(v)))) < 5e-3
    assert fitted.offset_ == pytest.approx(0.05, abs=2e-3)


def test_detector_map_recovered(fundamental) -> None:
    x, _, _ = fundamental
    y = x - 0.1 * x**2
    fitted, d, v = _fit(DetectorNonlinearity(), y)
    assert fitted.coef_[0] == pytest.approx(-0.1, rel=0.02)
    assert abs(fitted.coef_[1]) < 5e-3
    assert np.sqrt(np.mean((fitted.predict(d.take(v)) - y[v]) ** 2)) < 2e-3


def test_ac_bias_drive_recovers_a_fixed_second_harmonic(fundamental) -> None:
    x, _, phase = fundamental
    c2 = 0.03 * np.exp(0.4j)
    y = x + (c2 * np.exp(2j * phase)).real
    fitted, _, _ = _fit(AcBiasDrive(), y)
    got = fitted.coef_[0] - 1j * fitted.coef_[1]
    assert abs(got - c2) < 1e-3


def test_transfer_function_on_resonance() -> None:
    assert transfer(2) == pytest.approx(-1 / 3)
    assert transfer(3) == pytest.approx(-1 / 8)
    assert transfer(0) == pytest.approx(1.0)
    h = transfer(2, quality_factor=10.0)
    assert abs(h) == pytest.approx(1 / math.hypot(3, 0.2))
    # the lag of the 2nd harmonic's response departs from pi by ~ 2 / (3 Q)
    assert math.pi - abs(np.angle(h)) == pytest.approx(2 / 30, rel=0.01)


def test_gap_force_ties_the_dc_level_to_the_second_harmonic(fundamental) -> None:
    """A force f2 x^2 answers with dc f2 A^2/2 and 2nd harmonic f2 A^2/2 H(2): the
    gap-modulated model recovers f2; the detector map (dc ratio +1) fits it worse."""
    _, amp, phase = fundamental
    f2 = 0.15
    x = amp * np.cos(phase)
    y = x + f2 * amp**2 / 2 * (1 + transfer(2).real * np.cos(2 * phase))
    gap, d, v = _fit(GapModulatedForce(), y)
    det, _, _ = _fit(DetectorNonlinearity(), y)
    assert gap.coef_[0] == pytest.approx(f2, rel=0.02)
    err_gap = np.std(gap.predict(d.take(v)) - y[v])
    err_det = np.std(det.predict(d.take(v)) - y[v])
    assert err_gap < 0.2 * err_det


def test_quantisation_column_is_the_rounding_error(fundamental) -> None:
    x, _, _ = fundamental
    step = 0.05
    y = np.round(x / step) * step
    fitted, d, v = _fit(Quantisation(step=step), y)
    base, _, _ = _fit(LinearLever(), y)
    # 1 if the demodulated fundamental were exact; its own errors (a few % of a step) blur
    # the grid crossings
    assert 0.6 < fitted.coef_[0] < 1.1
    err = np.std(fitted.predict(d.take(v)) - y[v])
    assert err < 0.8 * np.std(base.predict(d.take(v)) - y[v])


def test_combined_holds_the_union_of_columns(fundamental) -> None:
    x, _, phase = fundamental
    y = x - 0.1 * x**2 + 0.02 * np.cos(2 * phase + 1.0)
    fitted, d, v = _fit(Combined([DetectorNonlinearity(), AcBiasDrive()]), y)
    assert fitted.coef_.shape == (4,)
    assert np.std(fitted.predict(d.take(v)) - y[v]) < 3e-3


def test_bad_settings_and_unfitted_use_raise() -> None:
    with pytest.raises(ValueError, match="frequency_hz"):
        HigherMode(frequency_hz=-1.0)
    with pytest.raises(ValueError, match="step"):
        Quantisation(step=0.0)
    with pytest.raises(ValueError, match="quality_factor"):
        GapModulatedForce(quality_factor=-2.0)
    with pytest.raises(ValueError, match="parts"):
        Combined([])
    y = np.cos(2 * math.pi * np.arange(2000) / FS)
    with pytest.raises(ValueError, match="not fitted"):
        DetectorNonlinearity().predict(demodulate(y, sample_rate_hz=FS))


def test_gap_force_requirement_known_values() -> None:
    from afmlearn.freeosc.evidence import gap_force_requirement
    out = gap_force_requirement(1.0, 0.5, harmonic_drift=0.03)
    # m = 1: F'/k >= 2 f2 A / 2 = 0.5; df/f >= 1/2 * 2/3 * 0.03 * 0.5 / 0.5 = 0.01
    assert out["m1"]["gradient_min"] == pytest.approx(0.5)
    assert out["m1"]["frequency_change_min"] == pytest.approx(0.01)
    assert gap_force_requirement(2.0, 0.6, harmonic_drift=0.0)["m1"]["frequency_change_min"] \
        == math.inf  # F'/k >= 1.2: the lever would snap in
