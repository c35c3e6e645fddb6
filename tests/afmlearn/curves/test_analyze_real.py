"""An Asylum On_Surface curve (../shared/data/real, MIT) carries both damping terms: the
far-field law measured on every 22--55 nm curve of the batch (docs/real_data.md, session 4)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from afmlearn.curves import CurveDiagnoser
from afmlearn.curves.analyze import damping_terms_si, load_curve
from afmlearn.curves.hypotheses import FREE_SCALE

ROOT = Path(__file__).resolve().parents[4] / "shared" / "data" / "real" / \
    "asylum_am_approach_curves"
CURVE = ROOT / "On_Surface" / "AZ_0052.ibw"

pytestmark = pytest.mark.skipif(not CURVE.is_file(),
                                reason=f"real Asylum curves not present at {ROOT}")


@pytest.mark.slow
def test_a_22nm_curve_gets_a_near_and_a_far_damping_term():
    """AZ_0052 (22 nm free amplitude): long_range_damping, both terms on, the far one at a
    tenth or so of the lever's own damping, the near one within a few nm; the retraction (never
    fitted) is predicted better. The far decay is not pinned by one curve: with the
    free-amplitude scale fitted (session 7) two basins fit it, ~550 nm with the scale at 1.00
    (far 0.07 x; session 8's batch at 2500 evaluations, both far starts kept, gain 0.775) and
    ~3.4 um with the scale at 1.13 (far 0.19 x; session 7's batch, data-read start only, gain
    0.771, chi2 0.78x), so the test takes either."""
    curve, lockin = load_curve(CURVE)
    diag = CurveDiagnoser(lockin=lockin, step=12.566, max_evaluations=1500).fit(curve)
    assert diag.cause_ == "long_range_damping"
    assert diag.gain_ > 0.3
    terms = {t["term"]: t for t in damping_terms_si(diag.extended_.law_, curve)}
    assert set(terms) == {"near", "far"}
    assert 300e-9 < terms["far"]["decay_length_m"] < 15e-6
    assert 0.03 < terms["far"]["times_lever_damping"] < 0.5
    assert 0.98 < diag.extended_.values_[FREE_SCALE] < 1.3
    # the longer the decay, the more of the loss is left at the ramp's start: a larger scale
    if terms["far"]["decay_length_m"] > 1.4e-6:
        assert diag.extended_.values_[FREE_SCALE] > 1.03
    assert terms["near"]["decay_length_m"] < 10e-9
    assert terms["near"]["times_lever_damping"] > 1.0
    assert math.isfinite(diag.report()["baseline"]["heldout_nrmse"])
