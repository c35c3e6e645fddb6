"""The curve law: compiled kernel against its NumPy reference, and both against the
simulator's force models (the project's force representation)."""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.curves import CurveLaw
from simulator.forces import DMT, Electrostatic, ExponentialDamping, ViscoelasticDMT

LAW = CurveLaw(a0=0.03, vdw=2e-5, stiffness=20.0, exponent=1.7, visco=0.3, damping=1e-3,
               decay_length=0.1, electrostatic=1e-4, radius=0.5, neck=0.02, far_damping=2e-4,
               far_decay_length=15.0)


@pytest.mark.parametrize("mode", [0, 1, 2])
def test_compiled_matches_reference(mode):
    rng = np.random.default_rng(mode)
    z = rng.uniform(0.0, 0.06, 200) if mode else rng.uniform(0.03, 2.0, 200)
    zd = rng.normal(0.0, 0.5, 200)
    ref = LAW.force(z, zd, mode)
    got = np.array([LAW.compiled(a, b, mode) for a, b in zip(z, zd, strict=True)])
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)


def test_same_force_as_the_simulator_models():
    z = np.linspace(0.005, 1.0, 500)
    zd = np.linspace(-0.4, 0.4, 500)
    dmt = DMT(a0=0.03, vdw=2e-5, stiffness=20.0, exponent=1.7)
    law = CurveLaw(a0=0.03, vdw=2e-5, stiffness=20.0, exponent=1.7)
    np.testing.assert_allclose(law.force(z, zd), dmt(z, zd), rtol=1e-12)
    visco = ViscoelasticDMT(a0=0.03, vdw=2e-5, stiffness=20.0, viscosity=0.3)
    np.testing.assert_allclose(CurveLaw(a0=0.03, vdw=2e-5, stiffness=20.0, visco=0.3)
                               .force(z, zd), visco(z, zd), rtol=1e-12)
    damp = ExponentialDamping(coefficient=1e-3, decay_length=0.1)
    es = Electrostatic(strength=1e-4, radius=0.5)
    extra = CurveLaw(a0=0.03, vdw=0.0, stiffness=1e-12, damping=1e-3, decay_length=0.1,
                     electrostatic=1e-4, radius=0.5)
    out = z > 0.03
    np.testing.assert_allclose(extra.force(z[out], zd[out]),
                               damp(z[out], zd[out]) + es(z[out], zd[out]), rtol=1e-12)
    # the far-field damping is a second exponential damping of the simulator's form
    far = ExponentialDamping(coefficient=3e-4, decay_length=20.0)
    two = CurveLaw(a0=0.03, vdw=0.0, stiffness=1e-12, damping=1e-3, decay_length=0.1,
                   far_damping=3e-4, far_decay_length=20.0)
    np.testing.assert_allclose(two.force(z[out], zd[out]),
                               damp(z[out], zd[out]) + far(z[out], zd[out]), rtol=1e-12)


def test_far_damping_is_one_more_term_and_off_at_zero():
    """The far-field term adds exactly ``-c exp(-z / z_f) z'``; at ``far_damping = 0`` the
    compiled kernel skips it (bit-identical whatever its decay length)."""
    z = np.linspace(0.01, 2.0, 50)
    zd = np.linspace(-0.3, 0.3, 50)
    off = LAW.replace(far_damping=0.0)
    for mode in (0, 1, 2):
        np.testing.assert_allclose(LAW.force(z, zd, mode) - off.force(z, zd, mode),
                                   -LAW.far_damping * np.exp(-z / LAW.far_decay_length) * zd,
                                   rtol=1e-7, atol=1e-14)
        got = [off.compiled(a, b, mode) for a, b in zip(z, zd, strict=True)]
        other = [off.replace(far_decay_length=3.0).compiled(a, b, mode)
                 for a, b in zip(z, zd, strict=True)]
        assert got == other
        np.testing.assert_allclose(got, off.force(z, zd, mode), rtol=1e-12, atol=1e-15)


def test_neck_holds_the_adhesion_and_dissipates():
    z = np.array([0.035, 0.045])
    np.testing.assert_allclose(LAW.force(z, 0.0, 2), -LAW.adhesion - LAW.electrostatic
                               / (z * (z + LAW.radius)))
    # approach (free) is less attractive than retraction (neck) at the same gap: a loss
    assert np.all(LAW.force(z, 0.0, 0) > LAW.force(z, 0.0, 2))


def test_bad_parameters_raise():
    with pytest.raises(ValueError, match="vdw"):
        CurveLaw(a0=0.03, vdw=-1.0)
    with pytest.raises(ValueError, match="exponent"):
        CurveLaw(a0=0.03, exponent=5.0)
    with pytest.raises(ValueError, match="a0"):
        CurveLaw(a0=0.0)
    with pytest.raises(ValueError, match="far_decay_length"):
        CurveLaw(a0=0.03, far_decay_length=0.0)
    with pytest.raises(ValueError, match="far_damping"):
        CurveLaw(a0=0.03, far_damping=-1e-4)
