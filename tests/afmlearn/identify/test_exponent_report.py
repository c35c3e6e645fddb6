"""The identifier's outputs never quote an unbounded contact exponent as the law (issue 14
audit: ``F_ts = 1093 delta^3.49996`` with an interval of 0.50-4.00).

The single-orbit refit itself runs in tests/scripts/test_identify_cli.py (its fixture's
30-period orbit does not bound the exponent); here the decisions on constructed summaries."""

from __future__ import annotations

from types import SimpleNamespace

from afmlearn.identify.fixed_exponent import SPHERE_EXPONENT, fixed_exponent_law
from afmlearn.identify.joint_outputs import format_exponent


def _fitted(p: float, interval: tuple[float, float], bounded: bool) -> SimpleNamespace:
    """A stand-in for a fitted identifier: only what the decision reads before any refit."""
    return SimpleNamespace(summary_={"interaction_exponent": p,
                                     "interaction_exponent_interval": interval,
                                     "interaction_exponent_bounded": bounded},
                           orbit_=None, joint_=None)


def test_a_bounded_exponent_is_quoted_as_fitted():
    assert fixed_exponent_law(_fitted(1.48, (1.3, 1.7), True)) is None


def test_unbounded_interval_excluding_the_sphere_fixes_nothing_and_says_which_end_holds():
    law = fixed_exponent_law(_fitted(3.84114, (2.5, 4.0), False))
    assert law is not None and law.exponent is None and law.model is None
    assert law.text.startswith("interaction exponent at least 2.50")
    assert "delta^3.84114" in law.text and "not an identified exponent" in law.text


def test_the_terminal_line_is_the_fixed_exponent_note_with_the_interval():
    note = ("interaction exponent 1.5 FIXED (sphere, Hertz/DMT): not identifiable from these "
            "data (95 % profile interval 0.50-4.00 reaches the end of the profiled range)")
    line = format_exponent({"interaction_exponent": 3.49996,
                            "interaction_exponent_interval": [0.5, 4.0],
                            "interaction_exponent_bounded": False,
                            "interaction_exponent_fixed": SPHERE_EXPONENT,
                            "interaction_exponent_note": note})
    assert line.startswith(note) and "3.50" not in line
    # without a note (a bounded exponent) the exponent and its interval, as before
    assert format_exponent({"interaction_exponent": 1.48,
                            "interaction_exponent_interval": [1.3, 1.7],
                            "interaction_exponent_bounded": True}) == \
        "interaction exponent 1.48 (95 % profile interval 1.30-1.70)"
