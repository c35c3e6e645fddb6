"""calibrate: dimensionless view of a trace and F_c from free data (against the simulator)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.io import Trace, read_trace
from afmlearn.preprocess import calibrate


def test_dimensionless_view(noisy_tapping):
    path, obj = noisy_tapping
    trace = read_trace(path)
    cal = calibrate(trace)
    ell = trace.gap_m
    np.testing.assert_allclose(cal.x, trace.deflection_m / ell, rtol=1e-15)
    # tau = omega0 t: the simulator's own sample interval
    np.testing.assert_allclose(np.diff(cal.tau), obj["result"].dt, rtol=1e-12)
    assert cal.gap == 1.0
    assert cal.omega == pytest.approx(1.0)
    assert cal.samples_per_period == pytest.approx(200.0)
    assert cal.dt == pytest.approx(obj["result"].dt)
    assert cal.quality_factor == 50.0
    assert cal.excitation == "tip" and not cal.excitation_assumed
    assert cal.scales.length == ell and cal.force_unit_n == pytest.approx(20.68 * ell)
    assert cal.tip_radius == pytest.approx(1.0)  # 10 nm tip, 10 nm gap
    assert cal.row is None and cal.n_periods == pytest.approx(20)


def test_drive_amplitude_from_the_free_trace_within_one_percent(noisy_tapping):
    """1 % noise on a 5-period free trace: F_c within 1 % of the simulator's drive B."""
    path, obj = noisy_tapping
    cal = calibrate(read_trace(path))
    assert cal.drive_source == "free_deflection"
    assert cal.drive_amplitude == pytest.approx(obj["excitation"].amplitude, rel=0.01)


def test_drive_amplitude_from_the_free_amplitude(noisy_tapping):
    path, obj = noisy_tapping
    trace = read_trace(path)
    meta = trace.metadata() | {"free_deflection_m": None}
    cal = calibrate(Trace(trace.deflection_m, **meta))
    assert cal.drive_source == "free_amplitude"
    assert cal.drive_amplitude == pytest.approx(obj["excitation"].amplitude, rel=1e-6)
    none = calibrate(Trace(trace.deflection_m, **(meta | {"free_amplitude_m": None,
                                                          "excitation": None})))
    assert none.drive_source == "none" and none.drive_amplitude is None
    assert none.excitation == "tip" and none.excitation_assumed


def test_base_excitation_reports_the_modal_forcing(tmp_path, simulate_tapping):
    """Dither y: the fundamental forcing is B_1 Omega^2 y with B_1 = 1.566 (rectangular beam)."""
    path = tmp_path / "base.h5"
    _, obj = simulate_tapping(path, "excitation=base", "noise.level=0.01",
                              "scenario.n_periods=5", "scenario.settle_periods=50")
    cal = calibrate(read_trace(path))
    y = obj["excitation"].amplitude
    assert cal.excitation == "base" and cal.dither == pytest.approx(y)
    b1 = obj["cantilever"].base_participation[0]
    assert cal.drive_amplitude == pytest.approx(b1 * cal.omega**2 * y, rel=0.01)


def _sweep_trace(*, excitation: str) -> tuple[Trace, float]:
    """A sweep whose free trace runs at Omega = 1 (the reference), rows at 0.97 and 1.02."""
    f0, q, fs, b = 100e3, 80.0, 100e3 * 256, 0.02
    om_free = 1.0
    amp = b / abs(1 - om_free**2 + 1j * om_free / q)
    t = np.arange(256 * 30) / fs
    free = amp * np.cos(om_free * 2 * np.pi * f0 * t + 0.3) * 1e-8
    rows = np.array([0.97, 1.02])
    deflection = np.vstack([0.5e-8 * np.cos(w * 2 * np.pi * f0 * t) for w in rows])
    trace = Trace(deflection, sample_rate_hz=fs, spring_constant_n_per_m=2.0,
                  quality_factor=q, resonance_frequency_hz=f0, drive_frequency_hz=rows * f0,
                  gap_m=1e-8, free_deflection_m=free, excitation=excitation)
    return trace, b


@pytest.mark.parametrize("excitation", ["tip", "base"])
def test_sweep_rows_carry_the_free_drive_over(excitation):
    trace, b = _sweep_trace(excitation=excitation)
    for row, om in enumerate([0.97, 1.02]):
        cal = calibrate(trace, row=row)
        assert cal.omega == pytest.approx(om) and cal.row == row
        expected = b * (om**2 if excitation == "base" else 1.0)
        assert cal.drive_amplitude == pytest.approx(expected, rel=1e-4)


def test_bad_rows_and_gap():
    trace, _ = _sweep_trace(excitation="tip")
    with pytest.raises(ValueError, match="row"):
        calibrate(trace)
    with pytest.raises(ValueError, match="row"):
        calibrate(trace, row=2)
    single = Trace(np.cos(np.arange(1000) * 0.1), sample_rate_hz=1e3,
                   spring_constant_n_per_m=1.0, quality_factor=10.0,
                   resonance_frequency_hz=1e3 / (20 * math.pi), drive_frequency_hz=15.0,
                   gap_m=-1e-9)
    with pytest.raises(ValueError, match="gap_m"):
        calibrate(single)
    with pytest.raises(ValueError, match="row"):
        calibrate(Trace(single.deflection_m, **(single.metadata() | {"gap_m": 1e-9})), row=1)
