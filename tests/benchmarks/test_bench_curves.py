"""The lock-in curve benchmark's group harness: joint starts from single-curve fits whose
long-range-damping fit carries the fitted free-amplitude scale (not a law field)."""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_curves import _without_free_scale  # noqa: E402

from afmlearn.curves import CurveLaw  # noqa: E402
from afmlearn.curves.group_diagnose import starts_from_singles  # noqa: E402
from afmlearn.curves.transfer import rescale_law  # noqa: E402


def _single(length_m: float, stiffness: float) -> SimpleNamespace:
    """A stand-in for a fitted CurveDiagnoser: a baseline and a damping fit whose values_
    hold the law, the curve's nuisances and (damping only) the free-amplitude scale."""
    base = CurveLaw(a0=0.03, vdw=1e-4, stiffness=stiffness)
    damp = base.replace(damping=0.02, decay_length=0.3)
    nuis = {"offset": 0.1, "omega": 1.0}
    return SimpleNamespace(
        curve_=SimpleNamespace(length_m=length_m),
        baseline_=SimpleNamespace(law_=base, values_={"vdw": base.vdw,
                                                      "stiffness": base.stiffness, **nuis}),
        fits_={"long_range_damping": SimpleNamespace(
            law_=damp, values_={"vdw": damp.vdw, "stiffness": damp.stiffness,
                                "damping": damp.damping, "decay_length": damp.decay_length,
                                "free_scale": 1.3, **nuis})})


def test_joint_starts_drop_the_free_scale_and_keep_the_si_law():
    singles = [_single(10e-9, 50.0), _single(40e-9, 80.0)]
    starts = starts_from_singles([_without_free_scale(d) for d in singles])
    damp = starts["long_range_damping"]
    assert len(damp) == 2 and all("free_scale" not in s["law"] for s in damp)
    assert all("free_scale" not in c for s in damp for c in s["curves"])
    # each start is its curve's law in the group unit (geometric mean 20 nm): the same SI force
    length = damp[0]["length_m"]
    assert length == pytest.approx(20e-9)
    for d, s in zip(singles, damp, strict=True):
        want = rescale_law(d.fits_["long_range_damping"].law_, d.curve_.length_m / length)
        assert s["law"]["stiffness"] == pytest.approx(want.stiffness)
        assert s["law"]["damping"] == pytest.approx(0.02)
        assert s["law"]["decay_length"] == pytest.approx(want.decay_length)
    assert damp[0]["law"]["stiffness"] != pytest.approx(damp[1]["law"]["stiffness"])


def _rec(ev_true: float, gain_true: float | None, ev_other: float = 0.0) -> dict:
    cands = sorted([{"cause": "electrostatic", "evidence": ev_true, "gain": gain_true},
                    {"cause": "drift", "evidence": ev_other, "gain": 0.1}],
                   key=lambda c: -c["evidence"])
    named = "drift" if ev_other > 10.0 and ev_other > ev_true else "none"
    return {"cause": "electrostatic", "index": 3, "named_joint": named,
            "candidates_joint": cands}


def _oracle(evidence: float, stuck: bool = False) -> dict:
    return {"evidence": evidence, "chi2_truth": 2.0 if stuck else 1.0, "chi2_baseline": 1.5}


@pytest.mark.parametrize(("rec", "oracle", "kind"), [
    (_rec(3.0, None), _oracle(4.0), ": invisible"),
    (_rec(3.0, None), _oracle(40.0), ": fit ("),
    (_rec(3.0, None), None, ": fit or invisible"),
    # a truth-started fit above the fitted baseline says nothing about visibility
    (_rec(3.0, None), _oracle(-900.0, stuck=True), ": fit or invisible"),
    (_rec(30.0, -0.02), _oracle(40.0), ": decision, refuted"),
    (_rec(30.0, 0.05, ev_other=80.0), _oracle(40.0), ": decision, outranked"),
])
def test_miss_class(rec, oracle, kind):
    from bench_curves import miss_class

    text = miss_class(rec, oracle)
    assert text.startswith(f"electrostatic #3 named {rec['named_joint']}")
    assert kind in text
