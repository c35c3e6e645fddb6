"""Every hypothesis nests the baseline and changes the model where its cause acts."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.diagnose.hypotheses import Context, default_hypotheses
from afmlearn.diagnose.spec import ModelSpec, neck_state
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
    att = neck_state(z, spec.a0, spec.neck_length)
    ext = spec.columns(z, zd, att)
    base = BASE.columns(z, zd)
    assert np.allclose(ext[:, : base.shape[1]], base)     # baseline columns unchanged
    assert spec.library().n_terms >= BASE.library().n_terms
    # the extension's own parameters change something
    if params:
        other = hyp.extend(BASE, [p.grid[-1] for p in params])
        assert other != BASE


def test_neck_state_holds_after_contact_until_the_snap():
    th = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    z = 1.0 + 1.1 * np.cos(th)                 # contact near theta = pi
    att = neck_state(z, 0.0, 0.2)
    contact = z <= 0
    leave = np.flatnonzero(contact)[-1] + 1
    assert att[contact].all()
    assert att[leave] and not att[(z > 0.2) & (th > np.pi)].any()
    assert not att[(th < np.pi) & (z > 0)].any()   # approach: no neck before contact
