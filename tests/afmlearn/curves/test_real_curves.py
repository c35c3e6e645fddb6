"""The Asylum AM approach curves of ../shared/data/real (MIT): read as curves, diagnosed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from afmlearn.curves import CurveDiagnoser
from afmlearn.curves.analyze import load_curve

ROOT = Path(__file__).resolve().parents[4] / "shared" / "data" / "real" / \
    "asylum_am_approach_curves"
ON = ROOT / "On_Surface" / "AZ_0052.ibw"

pytestmark = pytest.mark.skipif(not ON.is_file(),
                                reason=f"real Asylum curves not present at {ROOT}")


def test_asylum_curve_reads_with_calibration_and_segments():
    curve, lockin = load_curve(ON)
    assert curve.quality_factor == pytest.approx(187.36, rel=1e-3)
    assert curve.resonance_frequency_hz == pytest.approx(72350.0)
    assert 5e-9 < curve.length_m < 200e-9  # free amplitudes 11--175 nm
    assert set(np.unique(curve.segment)) == {0, 1}
    # 2 kHz samples on a 72 kHz lever: ~36 drive periods between samples
    assert (curve.tau[1] - curve.tau[0]) / (2 * math.pi) == pytest.approx(36.2, rel=0.02)
    assert 1.3 < curve.free_phase < 1.7  # Asylum's offset puts the free phase near 90 deg
    assert lockin is None or 0 < lockin.bandwidth < 0.5


@pytest.mark.slow
def test_asylum_curve_is_diagnosed():
    curve, lockin = load_curve(ON)
    diag = CurveDiagnoser(lockin=lockin, step=8 * 2 * math.pi).fit(curve)
    report = diag.report()
    assert report["cause"] in {"none", *[c["cause"] for c in report["candidates"]]}
    assert math.isfinite(report["baseline"]["heldout_nrmse"])
    assert report["gain"] >= 0.0
