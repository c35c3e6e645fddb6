"""The curve diagnosis' decision rule on hand-made candidates."""

from __future__ import annotations

import math

import pytest

from afmlearn.curves.diagnose import name_cause


def cand(cause, evidence, gain):
    return {"cause": cause, "evidence": evidence, "gain": gain}


def test_strongest_eligible_cause_is_named_with_its_bic_weight():
    scored, cause, conf, gain = name_cause(
        [cand("viscoelastic", 12.0, 0.1), cand("long_range_damping", 30.0, 0.2)],
        threshold=10.0)
    assert cause == "long_range_damping" and gain == 0.2
    expected = 1.0 / (1.0 + math.exp(-15.0) + math.exp(-9.0))
    assert conf == pytest.approx(expected)
    assert [c["cause"] for c in scored] == ["long_range_damping", "viscoelastic"]


def test_refuted_candidate_is_skipped_even_when_strongest():
    scored, cause, _, _ = name_cause(
        [cand("drift", 50.0, -0.1), cand("viscoelastic", 20.0, 0.05)], threshold=10.0)
    assert cause == "viscoelastic"
    assert scored[0]["cause"] == "drift" and scored[0]["score"] == 0.0


def test_weak_evidence_names_none_with_the_baseline_weight():
    _, cause, conf, gain = name_cause([cand("electrostatic", 4.0, 0.01)], threshold=10.0)
    assert cause == "none" and gain == 0.0
    assert conf == pytest.approx(1.0 / (1.0 + math.exp(2.0)))
    _, cause, conf, _ = name_cause([cand("electrostatic", 40.0, -0.01)], threshold=10.0)
    assert cause == "none" and conf == 1.0
