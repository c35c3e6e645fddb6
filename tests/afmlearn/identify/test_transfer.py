"""Transfer-function inversion against the simulator's true force (labels)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from afmlearn.identify.transfer import transfer_function_force
from afmlearn.io import Trace, read_trace
from afmlearn.metrics import force_accuracy
from afmlearn.preprocess import (
    HarmonicDerivatives,
    SavitzkyGolay,
    Spectral,
    calibrate,
)

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """Noiseless settled DMT tapping trace (Q = 50), 1000 samples per period, with labels."""
    from afmlearn.simulate import simulate

    path = tmp_path_factory.mktemp("transfer") / "clean.h5"
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[
            f"output={path}", "progress=false", "noise.level=0", "free_trace=false",
            "cantilever.quality_factor=50", "scenario.settle_periods=400",
            "scenario.n_periods=6", "scenario.samples_per_period=1000"])
    _, obj = simulate(cfg)
    trace = read_trace(path, labels=True)
    cal = calibrate(trace)
    res = obj["result"]
    b, theta0 = obj["excitation"].amplitude, res.phase[0]
    truth = {
        "force": trace.labels.force_n / cal.force_unit_n,
        "z": trace.labels.extra["tip_sample_gap_m"] / cal.scales.length,
        "a0": obj["force"].a0,
        # B cos(theta0 + Omega tau) = B cos(theta0) cos(Omega tau) - B sin(theta0) sin(...)
        "drive": (b * np.cos(theta0), -b * np.sin(theta0)),
    }
    return cal, truth


@pytest.mark.parametrize(("derivatives", "whole", "repulsive"), [
    (Spectral(), 0.9999, 0.9998),
    (HarmonicDerivatives(), 0.999, 0.998),
    (SavitzkyGolay(window=5), 0.9995, 0.999),
])
def test_exact_drive_recovers_the_true_force(clean, derivatives, whole, repulsive):
    cal, truth = clean
    bc, bs = truth["drive"]
    force = transfer_function_force(cal, drive_cos=bc, drive_sin=bs, derivatives=derivatives)
    acc = force_accuracy(force, truth["force"], truth["z"], truth["a0"])
    assert acc["whole"]["accuracy"] > whole
    assert acc["repulsive"]["accuracy"] > repulsive
    assert acc["whole"]["r2"] > 0.999
    assert acc["near_a0"]["n"] > 0 and acc["near_a0"]["accuracy"] > 0.99


def test_wrong_drive_phase_is_visible(clean):
    """The drive enters one to one: a 5 degree phase error leaves a sinusoidal force error."""
    cal, truth = clean
    bc, bs = truth["drive"]
    c, s = np.cos(np.radians(5)), np.sin(np.radians(5))
    force = transfer_function_force(cal, drive_cos=c * bc - s * bs, drive_sin=s * bc + c * bs,
                                    derivatives=Spectral())
    b = np.hypot(bc, bs)
    err = np.sqrt(np.nanmean((force - truth["force"]) ** 2))
    assert err == pytest.approx(b * 2 * np.sin(np.radians(2.5)) / np.sqrt(2), rel=0.02)


def test_free_linear_oscillator_gives_zero_force():
    """x = A cos(W tau + p) with A = B / |1 - W^2 + i W / Q|: the inversion returns 0."""
    q, om, b, spp = 30.0, 1.1, 0.05, 400
    h = 1.0 / (1 - om**2 + 1j * om / q)  # x = Re(B H e^{i W tau})
    tau = np.arange(10 * spp) * 2 * np.pi / (om * spp)
    x = np.real(b * h * np.exp(1j * om * tau))
    f0 = 1e5
    trace = Trace(x * 1e-8, sample_rate_hz=f0 * om * spp, spring_constant_n_per_m=1.0,
                  quality_factor=q, resonance_frequency_hz=f0, drive_frequency_hz=f0 * om,
                  gap_m=1e-8)
    cal = calibrate(trace)
    force = transfer_function_force(cal, drive_cos=b, drive_sin=0.0,
                                    derivatives=HarmonicDerivatives(n_harmonics=2))
    np.testing.assert_allclose(force, 0.0, atol=1e-10)
    # Savitzky-Golay (cubic, window 0.15 period): only the filter's smoothing bias remains,
    # it attenuates x'' of the fundamental by ~1.6 % (force error ~2 % of the amplitude |B H|)
    default = transfer_function_force(cal, drive_cos=b, drive_sin=0.0)
    err = np.max(np.abs(default[100:-100])) / abs(b * h)
    assert 0.005 < err < 0.03


def test_bad_input(clean):
    cal, _ = clean
    with pytest.raises(ValueError, match="drive_cos"):
        transfer_function_force(cal, drive_cos=np.nan, drive_sin=0.0)
    with pytest.raises(ValueError, match="derivatives"):
        transfer_function_force(cal, drive_cos=0.0, drive_sin=0.0, derivatives="savgol")
    with pytest.raises(ValueError, match="Calibrated"):
        transfer_function_force(cal.x, drive_cos=0.0, drive_sin=0.0)
