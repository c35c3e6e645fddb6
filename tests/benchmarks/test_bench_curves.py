"""The lock-in curve benchmark's group harness: why a joint diagnosis missed its cause."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_curves import miss_class  # noqa: E402


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
    text = miss_class(rec, oracle)
    assert text.startswith(f"electrostatic #3 named {rec['named_joint']}")
    assert kind in text
