"""What the diagnosis says about the contact exponent: the exponent the equations use, fixed
when the data do not bound it (issue 14 audit: "exponent 1.00 (1.00-3.50; not bounded)" next to
a baseline in delta^1.5), and the contact_geometry evidence when nothing moved."""

from __future__ import annotations

from types import SimpleNamespace

from afmlearn.diagnose.hypotheses.contact_geometry import ContactGeometry, exponent_summary


def test_unbounded_exponent_is_the_equations_fixed_one_not_the_profile_edge():
    ce = {"exponent": 1.0000000060705916, "interval_95": [1.0, 3.5], "bounded": False}
    txt = exponent_summary(ce, used=1.5)
    assert txt.startswith("1.5 (the sphere's), fixed in the equations")
    assert "not identifiable" in txt and "1.00-3.50" in txt
    assert not txt.startswith("1.00")
    # a named, freed exponent the data still do not bound: the equations' value, flagged
    named = exponent_summary({"exponent": 2.3, "interval_95": [1.0, 3.5], "bounded": False},
                             used=2.3)
    assert named.startswith("2.30 in the equations, but not identifiable")


def test_unbounded_exponent_that_excludes_the_equations_one_says_which_end_is_bounded():
    txt = exponent_summary({"exponent": 3.5, "interval_95": [2.4, 3.5], "bounded": False},
                           used=1.5)
    assert txt.startswith("at least 2.40") and "outside it" in txt


def test_bounded_exponent_is_printed_with_its_interval():
    named = exponent_summary({"exponent": 2.01, "interval_95": [1.8, 2.2], "bounded": True},
                             used=2.01)
    assert named == "2.01 (95 % interval 1.80-2.20)"
    kept = exponent_summary({"exponent": 1.62, "interval_95": [1.4, 1.85], "bounded": True},
                            used=1.5)
    assert kept.startswith("1.62 (95 % interval 1.40-1.85)")
    assert "the final equations use 1.5" in kept


def test_contact_geometry_evidence_says_what_changed_or_that_it_stayed():
    hyp = ContactGeometry()

    def evidence(p: float) -> str:
        model = SimpleNamespace(spec=SimpleNamespace(contact_exponent=p))
        return hyp.evidence(model, delta_chi2=0.0, gain=float("nan"))

    stayed = evidence(1.5)
    assert "stayed at the sphere's 1.5" in stayed and "instead of" not in stayed
    moved = evidence(2.01)
    assert "moved from the sphere's 1.5 to 2.01" in moved
    assert "held-out gain not computed" in moved
