"""AFM library terms: kernel == NumPy reference, potentials are exact antiderivatives, JSON."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.identify.library import (
    AFMLibrary,
    ContactIndicator,
    DeflectionPower,
    ExponentialDamping,
    GapRate,
    Indentation,
    IndentationRate,
    InversePower,
    SphereElectrostatic,
    TermInput,
    term_from_dict,
    term_to_dict,
)
from afmlearn.identify.library._kernel import force_series

LIB = AFMLibrary.standard()


def _orbit(n: int = 4001, a0: float = 0.03) -> TermInput:
    """A tapping-like orbit: z = 1 - 1.02 cos(tau), dipping below a0 and below zero."""
    tau = np.linspace(0, 4 * np.pi, n)
    x = 1.02 * np.cos(tau)
    return TermInput(z=1.0 - x, zdot=1.02 * np.sin(tau), x=x, a0=a0)


def test_standard_library_is_distinct_and_named():
    assert len(set(LIB.names)) == LIB.n_terms >= 30
    assert "delta^1.5" in LIB.names and "z^-2" in LIB.names and "[z<=a0]" in LIB.names


@pytest.mark.parametrize("j", range(LIB.n_terms))
def test_kernel_matches_numpy_reference(j):
    s = _orbit()
    ref = LIB[j].evaluate(s)
    kinds, p1, p2 = LIB.subset(np.arange(LIB.n_terms) == j).encode()
    got = force_series(kinds, p1, p2, np.ones(1), s.a0, s.z, s.zdot, s.x)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-300)


def test_library_codes_are_the_simulator_force_law_codes():
    """The library encodes its terms in the simulator's one force-law representation: every
    library family code names the same family there (the compiled evaluator is shared)."""
    from afmlearn.identify.library.base import Kind as LibKind
    from simulator.forces import Kind

    assert LibKind is Kind  # one table, not a copy kept in step
    codes = {v for k, v in vars(Kind).items() if k.isupper() and isinstance(v, int)}
    assert set(LIB.encode()[0].tolist()) <= codes  # every library term has a known family


@pytest.mark.parametrize("term", [t for t in LIB if t.potential(_orbit()) is not None],
                         ids=lambda t: t.name)
def test_potential_is_an_exact_antiderivative(term):
    """G(tau) - G(0) = int_0^tau theta along a smooth orbit (the weak form relies on it)."""
    from scipy.integrate import cumulative_trapezoid

    s = _orbit(n=200001)
    tau = np.linspace(0, 4 * np.pi, s.z.size)
    g = term.potential(s)
    integral = cumulative_trapezoid(term.evaluate(s), tau, initial=0.0)
    scale = np.max(np.abs(g - g[0])) or 1.0
    # trapezoid error at the contact switch (integrand jump x step / 2) sets the tolerance
    assert np.max(np.abs((g - g[0]) - integral)) < 1e-3 * scale


def test_contact_terms_vanish_out_of_contact_and_long_range_saturate():
    s = _orbit()
    out = s.z > s.a0
    for t in (ContactIndicator(), Indentation(1.5), IndentationRate(0.5)):
        assert np.all(t.evaluate(s)[out] == 0)
    v = InversePower(2.0).evaluate(s)
    np.testing.assert_allclose(v[~out], s.a0 ** -2)
    np.testing.assert_allclose(v[out], s.z[out] ** -2)


def test_json_roundtrip():
    again = AFMLibrary.from_list(LIB.to_list())
    assert again.names == LIB.names
    assert term_from_dict(term_to_dict(IndentationRate(0.5, 2))) == IndentationRate(0.5, 2)


@pytest.mark.parametrize("bad", [lambda: InversePower(0.0), lambda: Indentation(-1.0),
                                 lambda: IndentationRate(0.5, 3), lambda: GapRate(1.0, 0),
                                 lambda: ExponentialDamping(0.0),
                                 lambda: SphereElectrostatic(-1.0),
                                 lambda: DeflectionPower(1)])
def test_bad_parameters_raise_value_error(bad):
    with pytest.raises(ValueError):
        bad()


def test_library_rejects_duplicates_and_unknown_types():
    with pytest.raises(ValueError, match="distinct"):
        AFMLibrary([Indentation(1.5), Indentation(1.5)])
    with pytest.raises(ValueError, match="unknown term type"):
        term_from_dict({"type": "Nope"})
