"""diagnose_free on the measured Kelvin-probe deflection record (GPL file, never copied).

Reads ../shared/data/real/freqdemod_skpfm_cantilever/JAM_9p90__copy.h5 relative to the
repository root; skipped with the reason when it is absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from afmlearn.freeosc import diagnose_free
from afmlearn.io.instruments import open_recording

ROOT = Path(__file__).resolve().parents[3]
PATH = ROOT.parent / "shared" / "data" / "real" / "freqdemod_skpfm_cantilever" / \
    "JAM_9p90__copy.h5"
#: calibration: only the sampling rate (FreqDemod's notebook) is used; the rest are
#: placeholders the reader requires
CALIBRATION = {"sample_rate_hz": 1.15e6, "spring_constant_n_per_m": 1.0,
               "quality_factor": 1e4, "resonance_frequency_hz": 60.63e3,
               "drive_frequency_hz": 60.63e3, "gap_m": 5e-8}

pytestmark = pytest.mark.skipif(
    not PATH.exists(), reason=f"GPL real-data file not present at {PATH} (never copied into "
                              "the repository; see ../shared/data/real/README.md)")


def _record(n: int | None = None) -> np.ndarray:
    trace = open_recording(PATH, column="s", unit="nm", **CALIBRATION)
    y = np.asarray(trace.deflection_m) * 1e9
    return y if n is None else y[:n]


def test_a_part_of_the_record_names_a_cause_with_a_held_out_gain() -> None:
    y = _record(200_000)  # ~10,500 periods
    d = diagnose_free(y, sample_rate_hz=CALIBRATION["sample_rate_hz"], block_periods=500)
    assert d.cause != "none"
    assert d.gain > 0
    ev = d.evidence
    assert ev["samples_per_period"] == pytest.approx(19.0, abs=0.1)
    assert 0.05 < ev["relative_harmonics"][1] < 0.2  # the 2nd harmonic ~10 %


@pytest.mark.slow
def test_whole_record() -> None:
    y = _record()
    d = diagnose_free(y, sample_rate_hz=CALIBRATION["sample_rate_hz"], block_periods=1000)
    assert d.cause == "detector_nonlinearity"
    assert d.gain > 0.5
    # a fixed-amplitude 2 omega drive would give exponent 0
    h2 = d.evidence["scaling"]["h2"]
    assert h2["exponent"] > 3 * h2["exponent_stderr"]
    # a gap-modulated electrostatic force would need a frequency drift the record does not show
    gap = next(c for c in d.candidates if c["model"] == "GapModulatedForce")
    assert gap["excluded"]
    ac = next(c for c in d.candidates if c["model"] == "AcBiasDrive")
    assert ac["excluded"]  # the 2nd harmonic scales with A: not a fixed-amplitude drive
