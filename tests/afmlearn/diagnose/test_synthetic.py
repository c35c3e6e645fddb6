"""The hidden-effect generator: reproducible, labelled, tapping, and silent about the cause."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.diagnose.synthetic import CAUSES, draw_case
from afmlearn.io import read_trace


def test_draw_is_seeded_and_covers_the_vocabulary():
    a = [draw_case(np.random.default_rng([1, i])) for i in range(60)]
    b = [draw_case(np.random.default_rng([1, i])) for i in range(60)]
    assert a == b
    assert {c.cause for c in a} == set(CAUSES)
    for c in a:
        assert 150 <= c.quality_factor <= 450 and 1.2 <= c.free_amplitude_ratio <= 1.8
    with pytest.raises(ValueError, match="cause"):
        draw_case(np.random.default_rng(0), cause="gremlins")


def test_trace_carries_truth_only_in_labels(make_trace):
    path, case = make_trace("electrostatic", 5, spp=100, periods=30)
    tr = read_trace(path)
    assert tr.labels is None
    assert "electro" not in path.name and "electro" not in (tr.description or "")
    assert not hasattr(tr, "higher_mode_frequencies_hz") or tr.higher_mode_frequencies_hz is None
    lab = read_trace(path, labels=True).labels
    assert lab.effect == "electrostatic" == case.cause
    assert lab.scalars["regime"] == "repulsive"      # tapping orbits only
