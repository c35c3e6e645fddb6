"""Every hypothesis nests the baseline and changes the model where its cause acts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from afmlearn.diagnose.hypotheses import (
    Context,
    DetectorMap,
    ElectrostaticTerm,
    Neck,
    SecondMode,
    ViscoelasticTerm,
    default_hypotheses,
)
from afmlearn.diagnose.spec import AbstractOutputMap, ModelSpec, neck_state
from afmlearn.diagnose.synthetic import EFFECT_CAUSES

CTX = Context(length_m=1e-8, amplitude=1.3, z_min=-0.1, z_max=2.5, tip_radius=1.0)
BASE = ModelSpec(a0=0.03, drive_phase=0.1)


def test_one_hypothesis_per_cause():
    assert tuple(h.cause for h in default_hypotheses()) == EFFECT_CAUSES


@pytest.mark.parametrize("hyp", default_hypotheses(), ids=lambda h: h.cause)
def test_extension_nests_the_baseline(hyp):
    params = hyp.parameters(CTX)
    for p in params:
        assert p.low < p.high
        assert all(p.low <= g <= p.high for g in p.grid)
    spec = hyp.extend(BASE, hyp.nested_values(params))
    z = np.linspace(-0.1, 2.5, 400)
    zd = np.cos(np.linspace(0, 2 * np.pi, 400))
    att = spec.state(z)
    ext = spec.columns(z, zd, att)
    base = BASE.columns(z, zd)
    assert np.allclose(ext[:, : base.shape[1]], base)     # baseline columns unchanged
    assert spec.library().n_terms >= BASE.library().n_terms
    # the extension adds exactly one extension object (contact_geometry: frees the exponent)
    assert len(spec.extensions) == (hyp.cause != "contact_geometry")
    # the extension's own parameters reach the model (not only the nested point)
    if params:
        other = hyp.extend(BASE, [p.grid[-1] for p in params])
        assert other != spec and other.term_keys() == spec.term_keys()


def test_neck_state_holds_after_contact_until_the_snap():
    th = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    z = 1.0 + 1.1 * np.cos(th)                 # contact near theta = pi
    att = neck_state(z, 0.0, 0.2)
    contact = z <= 0
    leave = np.flatnonzero(contact)[-1] + 1
    assert att[contact].all()
    assert att[leave] and not att[(z > 0.2) & (th > np.pi)].any()
    assert not att[(th < np.pi) & (z > 0)].any()   # approach: no neck before contact


def test_spec_holds_one_extension_per_key_ordered_by_role():
    """Extensions are stored by role (force terms in their canonical order, then neck, extra
    mode, output map); the same key replaces in place; the kernel's single roles are refused
    twice."""
    spec = BASE.with_extension(DetectorMap(0.1, 0.0)).with_extension(Neck(0.2))
    spec = spec.with_extension(ElectrostaticTerm(0.5)).with_extension(ViscoelasticTerm(0.5))
    assert [e.key for e in spec.extensions] == ["visco", "electrostatic", "neck", "detector"]
    assert spec.term_keys() == ["vdw", "contact", "visco", "electrostatic", "neck"]
    assert spec.signs() == [-1, 1, 1, -1, 1]   # the JKR neck's stiffness is >= 0
    assert spec.state_key == ("neck", "detector")
    moved = spec.with_extension(ElectrostaticTerm(0.7))
    assert moved.get(ElectrostaticTerm).radius == 0.7 and moved.term_keys() == spec.term_keys()
    with pytest.raises(ValueError, match="distinct keys"):
        ModelSpec(a0=0.03, extensions=(Neck(0.1), Neck(0.2)))

    @dataclass(frozen=True)
    class OtherMap(AbstractOutputMap):
        key = "other_map"

        def polynomial(self):
            return (0.0,)

        def report(self, scales):
            return {}

    with pytest.raises(ValueError, match="at most one AbstractOutputMap"):
        spec.with_extension(OtherMap())
    with pytest.raises(ValueError, match="extensions"):
        ModelSpec(a0=0.03, extensions=("neck",))


def test_extra_mode_and_output_map_hooks_give_the_model_equations():
    """The role bases turn the hooks into the model's numbers: modal (K2, D2, g2), the mode's
    response at a harmonic, the measured map and its inverse."""
    m = SecondMode(6.2, 500.0, 0.8)
    k2, d2, g2 = m.modal()
    assert (k2, d2, g2) == (6.2**2, 6.2 / 500.0, 0.8)
    n = np.arange(4)
    assert np.allclose(m.response(n, 1.1), 1 / (k2 - (1.1 * n) ** 2 + 1j * 1.1 * n * d2))
    det = DetectorMap(0.05, -0.02)
    x = np.linspace(-1.2, 1.2, 41)
    assert np.allclose(det.invert(det.measure(x)), x, rtol=0, atol=1e-12)
