"""check_trace / check_deflection: one test per bad-input case, and clean data pass."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from afmlearn.io import Trace, TraceFormatError, read_trace, write_trace
from afmlearn.preprocess import (
    CalibrationError,
    ClippedSignalError,
    InputError,
    NonFiniteError,
    TooShortError,
    UndersampledError,
    check_deflection,
    check_trace,
    clipped_run,
)

F0 = 250e3


def _trace(x: np.ndarray, *, spp: float = 1500.0, **extra) -> Trace:
    meta = dict(sample_rate_hz=F0 * spp, spring_constant_n_per_m=20.0, quality_factor=400.0,
                resonance_frequency_hz=F0, drive_frequency_hz=F0, gap_m=10e-9)
    return Trace(x, **(meta | extra))


def _sinusoid(n_periods: float = 10, spp: float = 1500.0, phase: float = 0.3) -> np.ndarray:
    k = np.arange(int(n_periods * spp))
    return 12e-9 * np.cos(2 * np.pi * k / spp + phase)


def _quantise(x: np.ndarray, bits: int, full_scale: float) -> np.ndarray:
    step = 2 * full_scale / 2**bits
    return np.round(x / step) * step


def test_clean_simulated_trace_passes(noisy_tapping, noiseless_tapping):
    for path, _ in (noisy_tapping, noiseless_tapping):
        check_trace(read_trace(path))


@pytest.mark.parametrize("bits", [16, 12])
def test_quantised_sinusoid_is_not_flagged(bits):
    x = _quantise(_sinusoid(), bits, full_scale=12.5e-9)
    run, limit = clipped_run(x, samples_per_period=1500)
    assert 2 <= run <= limit  # the peaks do sit on one ADC level for a few samples
    check_trace(_trace(x))


def test_clipped_sinusoid_is_flagged():
    x = _sinusoid()
    clipped = np.clip(x, -0.95 * 12e-9, 0.95 * 12e-9)
    run, _ = clipped_run(clipped, samples_per_period=1500)
    # acos(0.95) / pi of each period sits at the clip level
    assert run == pytest.approx(1500 * np.arccos(0.95) / np.pi, abs=2)
    with pytest.raises(ClippedSignalError, match="clipped"):
        check_trace(_trace(clipped))
    # one-sided saturation (detector range), quantised: still flagged
    one_sided = _quantise(np.minimum(x, 0.95 * 12e-9), 16, full_scale=12.5e-9)
    with pytest.raises(ClippedSignalError):
        check_trace(_trace(one_sided))


def test_undersampled_and_too_short():
    with pytest.raises(UndersampledError, match="samples per drive period"):
        check_trace(_trace(_sinusoid(spp=15), spp=15))
    check_trace(_trace(_sinusoid(spp=20), spp=20))
    with pytest.raises(TooShortError, match="periods"):
        check_trace(_trace(_sinusoid(n_periods=2.5)))
    with pytest.raises(UndersampledError):
        check_trace(_trace(_sinusoid(spp=40), spp=40), min_samples_per_period=50)


def test_nan_is_refused(tmp_path):
    x = _sinusoid()
    x[100] = np.nan
    with pytest.raises(NonFiniteError, match="NaN"):
        check_deflection(x, samples_per_period=1500)
    # a Trace cannot hold NaN; a file with NaN is refused by the reader (a ValueError)
    path = tmp_path / "t.h5"
    write_trace(_trace(_sinusoid()), path)
    with h5py.File(path, "r+") as f:
        f["deflection_m"][100] = np.nan
    with pytest.raises(TraceFormatError, match="NaN"):
        read_trace(path)


def test_bad_calibration():
    with pytest.raises(CalibrationError, match="gap_m"):
        check_trace(_trace(_sinusoid(), gap_m=0.0))
    with pytest.raises(CalibrationError):
        check_trace(_sinusoid())  # not a Trace
    assert issubclass(CalibrationError, InputError) and issubclass(InputError, ValueError)


def test_sweep_rows_are_named():
    good = _sinusoid(n_periods=5)
    bad = np.clip(good, -0.9 * 12e-9, 0.9 * 12e-9)
    sweep = _trace(np.vstack([good, bad]), drive_frequency_hz=np.array([F0, F0]))
    check_trace(sweep, row=0)
    with pytest.raises(ClippedSignalError, match="row 1"):
        check_trace(sweep)
