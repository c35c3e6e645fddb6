"""Demodulation and per-block harmonics against signals with a known answer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from afmlearn.freeosc import demodulate, track_harmonics
from afmlearn.freeosc.track import amplitude_scaling

FS = 19.0  # samples per unit frequency: ~19 samples per period at f = 1


def _chirp(n: int = 60_000) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) / FS
    freq = 1.0 + 2e-3 * np.sin(2 * math.pi * t / 1500)
    phase = 2 * math.pi * np.cumsum(freq) / FS + 0.4
    amp = 1.0 + 0.2 * np.sin(2 * math.pi * t / 2100)
    return t, amp, phase, freq


def test_amplitude_phase_and_frequency_of_a_modulated_sinusoid() -> None:
    _, amp, phase, freq = _chirp()
    y = amp * np.cos(phase) + 0.3 * (amp * np.cos(phase)) ** 2  # harmonics must be rejected
    d = demodulate(y, sample_rate_hz=FS)
    v = d.valid
    assert d.carrier_hz == pytest.approx(1.0, rel=2e-3)
    assert np.max(np.abs(d.amplitude[v] - amp[v])) < 2e-3
    wrapped = np.angle(np.exp(1j * (d.phase[v] - phase[v])))
    assert np.max(np.abs(wrapped)) < 2e-3
    assert np.max(np.abs(d.frequency_hz[v] - freq[v])) < 1e-3


def test_demodulation_agrees_with_the_analytic_signal_reference() -> None:
    """Plain reference: band-pass + Hilbert transform (scipy) on a clean sinusoid."""
    _, amp, phase, _ = _chirp(40_000)
    y = amp * np.cos(phase)
    d = demodulate(y, sample_rate_hz=FS)
    sos = signal.butter(4, [0.5, 1.5], "bandpass", fs=FS, output="sos")
    ref = signal.hilbert(signal.sosfiltfilt(sos, y))
    v = d.valid
    assert np.max(np.abs(d.amplitude[v] - np.abs(ref)[v])) < 5e-3


def test_harmonics_follow_a_detector_map_with_exponent_n() -> None:
    _, amp, phase, _ = _chirp()
    b2, b3 = -0.2, 0.05
    x = amp * np.cos(phase)
    y = x + b2 * x**2 + b3 * x**3
    d = demodulate(y, sample_rate_hz=FS)
    tr = track_harmonics(y, d, n_harmonics=9, block_periods=100)
    a = tr.amplitude.copy()  # measured |X_1| = A + 3/4 b3 A^3: solve for the true A
    for _ in range(20):
        a = tr.amplitude - 0.75 * b3 * a**3
    # R_2 = b2 A^2 / 2 (real, negative); R_3 = b3 A^3 / 4
    np.testing.assert_allclose(tr.harmonics[:, 1], b2 * a**2 / 2, rtol=0.02, atol=2e-3)
    np.testing.assert_allclose(tr.harmonics[:, 2].real, b3 * a**3 / 4, rtol=0.05, atol=1e-3)
    # the exponent is measured against |X_1|, which b3 bends: expected slope from the truth
    la = np.log(tr.amplitude)
    for n, expected in ((2, np.log(abs(b2) * a**2 / 2)), (3, np.log(b3 * a**3 / 4))):
        slope = np.polyfit(la, expected, 1)[0]
        assert 1.5 < slope < n + 0.5
        assert amplitude_scaling(tr, n).exponent == pytest.approx(slope, abs=0.05 * n)


def test_bad_settings_raise_naming_the_parameter() -> None:
    with pytest.raises(ValueError, match="sample_rate_hz"):
        demodulate(np.ones(100), sample_rate_hz=-1.0)
    with pytest.raises(ValueError, match="at least 64"):
        demodulate(np.ones(10), sample_rate_hz=1.0)
    _, amp, phase, _ = _chirp(5000)
    y = amp * np.cos(phase)
    d = demodulate(y, sample_rate_hz=FS)
    with pytest.raises(ValueError, match="block_periods"):
        track_harmonics(y, d, block_periods=2)
    with pytest.raises(ValueError, match="block_periods"):
        track_harmonics(y, d, block_periods=100_000)
