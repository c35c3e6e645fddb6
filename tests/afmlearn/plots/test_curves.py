"""afmlearn.plots.curves: residuals (sign, units), SI values of the fitted parameters, the flags
of values a curve does not identify, and the figures drawn from a stub diagnoser."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from afmlearn.curves import Curve
from afmlearn.curves.hypotheses import BASELINE, EXTENSIONS
from afmlearn.plots.curves import (
    _parameter_flag,
    _si_parameters,
    curve_figures,
    curve_residuals,
    plot_parameter_spread,
    spread_table,
)

K, F0, A_FREE = 2.7, 72e3, 50e-9


def _curve() -> Curve:
    """Approach then retraction of a made-up curve: amplitude falls in the last free amplitude."""
    z = np.concatenate([np.linspace(500e-9, 0.0, 200), np.linspace(0.0, 500e-9, 200)])
    amp = A_FREE * np.clip(z / A_FREE, 0.2, 1.0)
    phase = np.full_like(z, math.pi / 2) + 0.3 * (amp < A_FREE)
    seg = np.r_[np.zeros(200), np.ones(200)]
    return Curve.from_si(amplitude_m=amp, phase_rad=phase, z_piezo_m=z, segment=seg,
                         sample_rate_hz=2e3, quality_factor=187.0, spring_constant_n_per_m=K,
                         resonance_frequency_hz=F0)


class _Fit:
    """A fitted model that predicts the data times ``scale`` and shifted by ``dphi``."""

    def __init__(self, curve: Curve, scale: float, dphi: float) -> None:
        self.c, self.scale, self.dphi = curve, scale, dphi
        self.values_ = {"offset": 0.0, "omega": 1.0}
        self.law_ = SimpleNamespace(a0=0.3e-9 / A_FREE,
                                    conservative=lambda z: -1e-5 / np.maximum(z, 6e-3) ** 2)

    def predict(self, curve):
        return curve.amplitude * self.scale, curve.phase + self.dphi

    def gap(self, curve):
        return curve.z_piezo - self.values_["offset"]


def _diag(cause: str = "long_range_damping"):
    c = _curve()
    base, ext = _Fit(c, 0.98, math.radians(-2.0)), _Fit(c, 1.0, 0.0)
    return SimpleNamespace(curve_=c, baseline_=base, extended_=ext if cause != "none" else base,
                           cause_=cause, confidence_=1.0, gain_=0.5, baseline_heldout_=0.02,
                           dissipation=lambda: np.zeros(c.n))


def test_residuals_are_data_minus_model_in_percent_and_degrees():
    d = _diag()
    res = curve_residuals(d)
    assert set(res) == {"baseline", "extended (long_range_damping)"}
    ra, rp = res["baseline"]
    # the baseline predicts 2 % less amplitude and 2 deg less lag than measured
    np.testing.assert_allclose(ra, 2.0 * d.curve_.amplitude, rtol=1e-12)
    np.testing.assert_allclose(rp, 2.0, rtol=1e-9)
    np.testing.assert_allclose(res["extended (long_range_damping)"][0], 0.0, atol=1e-12)
    # wrapped: a lag off by a whole turn is no residual
    d.baseline_.dphi = 2 * math.pi
    np.testing.assert_allclose(curve_residuals(d)["baseline"][1], 0.0, atol=1e-9)
    assert set(curve_residuals(_diag("none"))) == {"baseline"}


def test_figures_are_written(tmp_path):
    paths = curve_figures(_diag(), tmp_path)
    assert [p.name for p in paths] == ["curve_fit.png", "curve_force.png",
                                       "curve_dissipation.png"]
    for p in paths:
        assert p.read_bytes()[:4] == b"\x89PNG"


def test_flags_bounds_starts_and_grid_values_not_fitted_values():
    stiffness = BASELINE.parameters[1]
    assert _parameter_flag("stiffness", stiffness.low) == "bound"
    assert _parameter_flag("stiffness", stiffness.high * 0.999) == "bound"
    damping = next(h for h in EXTENSIONS if h.cause == "long_range_damping").parameters[0]
    assert _parameter_flag("damping", damping.init) == "start"
    assert _parameter_flag("damping", damping.alternatives[0]) == "start"
    for grid in (1.0, 3.0, 30.0, 0.25, 2.5e-6):  # products of start-grid values
        assert _parameter_flag("stiffness", grid) == "start"
    for fitted in (7.846209115917913, 426.83998561902405, 1.4124817629983327e-05, 0.0695):
        assert _parameter_flag("stiffness", fitted) is None


def _row(cause, **ext):
    base = {"offset": -13.1, "omega": 0.9998, "vdw": 3.019e-05, "stiffness": 10.17}
    return {"group": "On", "cause": cause, "gain": 0.2, "free_amplitude_m": A_FREE,
            "adhesion_force_n": 3.4e-9, "spring_constant_n_per_m": K,
            "resonance_frequency_hz": F0, "baseline_parameters": base,
            "parameters": {**base, **ext}}


def test_si_parameters_give_the_same_force_as_the_dimensionless_law():
    w0 = 2 * math.pi * F0
    L = A_FREE
    si = _si_parameters(_row("long_range_damping", damping=2.3e-3, decay_length=0.73))
    # contact stiffness: s delta^1.5 [nN] at delta = 3 nm equals stiffness (delta/L)^1.5 k L
    s_si, flag = si["contact stiffness, baseline [nN/nm^1.5]"]
    assert flag is None
    assert s_si * 3.0**1.5 == pytest.approx(10.17 * (3e-9 / L) ** 1.5 * K * L * 1e9, rel=1e-12)
    # damping force gamma v [N] at v = 1 mm/s equals damping (v / (L w0)) k L
    assert si["long-range damping [N s/m]"][0] * 1e-3 == pytest.approx(
        2.3e-3 * (1e-3 / (L * w0)) * K * L, rel=1e-12)
    assert si["damping decay length [nm]"][0] == pytest.approx(0.73 * L * 1e9)
    assert si["adhesion, named model [nN]"] == (pytest.approx(3.4), None)
    assert "adhesion neck length [nm]" not in si  # only where that cause is named
    neck = _si_parameters(_row("adhesion_hysteresis", neck=0.0695))
    assert neck["adhesion neck length [nm]"][0] == pytest.approx(0.0695 * L * 1e9)
    # eta sqrt(delta) delta_dot [N] at delta = 2 nm, 1 mm/s equals visco sqrt(d/L) (v/(L w0)) kL
    eta = _si_parameters(_row("viscoelastic", visco=0.9))["viscoelastic coefficient [N s/m^1.5]"]
    assert eta[0] * math.sqrt(2e-9) * 1e-3 == pytest.approx(
        0.9 * math.sqrt(2e-9 / L) * (1e-3 / (L * w0)) * K * L, rel=1e-12)
    assert math.isnan(_si_parameters(_row("none"))["held-out gain"][0])


def test_adhesion_is_not_identified_when_the_contact_stiffness_is_not():
    row = _row("long_range_damping", damping=2.3e-3, decay_length=0.73)
    row["parameters"]["stiffness"] = 1.0  # a start-grid value: never moved
    assert _si_parameters(row)["adhesion, named model [nN]"][1] == "start"


def test_parameter_spread_leaves_out_unidentified_values(tmp_path):
    rows = [_row("long_range_damping", damping=d, decay_length=0.73)
            for d in (2.317e-3, 4.093e-3, 1e-3)]  # the last one stayed at its start
    rows.append(_row("adhesion_hysteresis", neck=0.0695))
    rows[1]["group"] = "Off"
    table = spread_table(rows)
    data, flags = table["long-range damping [N s/m]"]
    assert sorted(data) == ["Off", "On"] and data["On"].size == 1 and data["Off"].size == 1
    assert flags == {"start": 1}
    data, flags = table["adhesion neck length [nm]"]
    assert data["On"].size == 1 and not flags
    assert table["free amplitude [nm]"][0]["On"].size == 3
    path = plot_parameter_spread(rows, tmp_path)
    assert path.name == "parameter_spread.png" and path.read_bytes()[:4] == b"\x89PNG"


def test_far_field_terms_are_shown_with_their_flags_in_the_curves_unit():
    """The far decay's start and bounds are metres (``si_length``): compared in the curve's
    unit; the far term and the free-amplitude scale get panels in SI."""
    far = {"far_damping": 1.234e-4, "far_decay_length": 2317e-9 / A_FREE,
           "free_scale": 1.0853}
    si = _si_parameters(_row("long_range_damping", damping=2.3e-3, decay_length=0.73, **far))
    assert si["far-field decay length [nm]"] == (pytest.approx(2317.0, rel=1e-12), None)
    assert si["far-field damping [N s/m]"][0] == pytest.approx(1.234e-4 * K / (2 * math.pi * F0))
    assert si["free-amplitude scale (drive's / ramp start's)"] == (1.0853, None)
    assert _parameter_flag("far_decay_length", 500e-9 / A_FREE, A_FREE) == "start"
    assert _parameter_flag("far_decay_length", 20e-9 / A_FREE, A_FREE) == "bound"
    assert _parameter_flag("free_scale", 1.0) == "start"
