"""Force models: compiled kernel vs NumPy reference, continuity, signs, limits, SI conversion.

Everything is dimensionless (gap / rest gap, force / (k L_ref)); the SI set-up of
``simcases.SCALES`` is k = 40 N/m, f0 = 300 kHz, L_ref = 10 nm, so the force unit is 4e-7 N.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from simcases import CONSERVATIVE, DISSIPATIVE, DMT_PARAMS, FORCE_MODELS, SCALES

from simulator import Scales
from simulator.forces import (
    DMT,
    JKR,
    AbstractForceModel,
    Electrostatic,
    ExponentialDamping,
    ForceSum,
    HystereticJKR,
    LennardJones,
    SphereVdW,
    ViscoelasticDMT,
)
from simulator.forces._kernel import law_force, term_value
from simulator.forces.law import Kind

FORCE_UNIT = 4e-7  # k L_ref [N]
CONTACT_MODELS = [n for n, m in FORCE_MODELS.items() if m.has_contact]
SMOOTH_CONTACT = [n for n in CONTACT_MODELS if FORCE_MODELS[n].break_indentation == 0.0]
RATE_MODELS = ["visco", "visco_q1", "dmt+expdamp", "jkr_hysteretic+expdamp", "sum3"]


def kernel(model: AbstractForceModel, z, zdot, contact) -> np.ndarray:
    """The compiled ``law_force`` of ``model.law()`` evaluated point by point (the simulator's
    carried regime: ``contact == attached``)."""
    law = model.law()
    kinds, p1, p2, c = law.arrays
    z, zdot, contact = np.broadcast_arrays(np.asarray(z, float), np.asarray(zdot, float),
                                           np.asarray(contact, bool))
    out = np.empty(z.shape)
    for i in np.ndindex(z.shape):
        out[i] = law_force(kinds, p1, p2, c, law.a0, float(z[i]), float(zdot[i]), 0.0,
                           bool(contact[i]), bool(contact[i]))
    return out


def physical_points(model: AbstractForceModel, n: int = 400, seed: int = 0):
    """Random (z, zdot, contact) in the region a trajectory can visit.

    Out of contact ``a0 < z < 3``; in contact ``a0 - 0.15 <= z <= a0 - break_indentation``
    (up to the neck for the hysteretic JKR); ``|zdot| < 2``.
    """
    rng = np.random.default_rng(seed)
    zdot = rng.uniform(-2.0, 2.0, n)
    if not model.has_contact:
        low = 0.15 if isinstance(model, LennardJones) else 0.05
        return rng.uniform(low, 3.0, n), zdot, np.zeros(n, bool)
    a0, brk = model.a0, model.break_indentation
    half = n // 2
    z = np.concatenate([rng.uniform(a0, 3.0, half), rng.uniform(a0 - 0.15, a0 - brk, n - half)])
    z[0], z[half] = a0 * (1 + 1e-15), a0 - brk  # the ends of each branch
    contact = np.arange(n) >= half
    return z, zdot, contact


# ------------------------------------------------------------------ kernel == reference
@pytest.mark.parametrize("name", list(FORCE_MODELS))
def test_kernel_matches_reference(name: str) -> None:
    model = FORCE_MODELS[name]
    z, zdot, contact = physical_points(model)
    ref = model(z, zdot, contact)
    fast = kernel(model, z, zdot, contact)
    scale = max(np.max(np.abs(ref)), 1e-300)
    np.testing.assert_allclose(fast, ref, rtol=1e-12, atol=1e-13 * scale)


def test_repeated_terms_add() -> None:
    """The term list holds repeated families the old fixed coefficient vector refused: two
    electrostatic spheres, two damping lengths, two van der Waals radii on one DMT contact."""
    m = (_dmt() + Electrostatic(strength=0.01, radius=1.0) + Electrostatic(strength=0.02,
                                                                           radius=3.0)
         + ExponentialDamping(coefficient=0.1, decay_length=0.1)
         + ExponentialDamping(coefficient=0.2, decay_length=0.5)
         + SphereVdW(strength=1e-3, radius=1.0) + SphereVdW(strength=2e-3, radius=2.0))
    z, zdot, contact = physical_points(m)
    parts = [t(np.where(contact, m.a0, z) if t.saturates_in_contact else z, zdot, contact)
             for t in m.terms]
    np.testing.assert_allclose(kernel(m, z, zdot, contact), np.sum(parts, axis=0),
                               rtol=1e-12, atol=1e-15)
    assert m.law().n_terms == 8 and m.dissipative


@pytest.mark.parametrize("name", list(FORCE_MODELS))
def test_dissipative_flag(name: str) -> None:
    assert FORCE_MODELS[name].dissipative == (name in DISSIPATIVE)
    assert (name in CONSERVATIVE) != (name in DISSIPATIVE)


# ------------------------------------------------------------------ continuity at a0
@pytest.mark.parametrize("name", SMOOTH_CONTACT)
@pytest.mark.parametrize("impl", ["reference", "kernel"])
def test_continuous_at_contact_onset(name: str, impl: str) -> None:
    """DMT-type laws join the tail at ``z = a0`` for any rate (the rate term ~ delta**q)."""
    model = FORCE_MODELS[name]
    f = model if impl == "reference" else (lambda z, zd, c: kernel(model, z, zd, c))
    a0 = model.a0
    zd = np.array([-1.3, 0.0, 0.7])
    one = np.ones_like(zd)
    np.testing.assert_allclose(f(a0 * one, zd, True), f(a0 * one, zd, False), rtol=1e-13,
                               atol=1e-15)
    # one-sided limits: the jump over [a0 - eps, a0 + eps] vanishes as eps -> 0
    jumps = [np.max(np.abs(f((a0 - e) * one, zd, True) - f((a0 + e) * one, zd, False)))
             for e in (1e-4, 1e-6, 1e-8)]
    assert jumps[2] < 0.011 * jumps[0] + 1e-13, jumps  # at least ~ sqrt(eps) (visco, q = 0.5)


@pytest.mark.parametrize("impl", ["reference", "kernel"])
def test_hysteretic_jkr_forms_continuously_and_snaps_at_the_neck(impl: str) -> None:
    m = FORCE_MODELS["jkr_hysteretic"]
    f = m if impl == "reference" else (lambda z, zd, c: kernel(m, z, zd, c))
    a0, brk = m.a0, m.break_indentation
    assert brk < 0.0
    assert f(a0, 0.0, True) == pytest.approx(float(f(a0, 0.0, False)), rel=1e-12)
    neck = float(f(a0 - brk, 0.0, True))
    tail = float(f(a0 - brk, 0.0, False))
    # on breaking, the force jumps up to the (weaker) tail: the energy of the loop is lost
    assert tail - neck > 0.05 * abs(neck)


# ------------------------------------------------------------------ sign conventions
ATTRACTIVE = [n for n in FORCE_MODELS if n != "none"]


@pytest.mark.parametrize("name", ATTRACTIVE)
def test_attractive_tail_is_negative_and_decays(name: str) -> None:
    model = FORCE_MODELS[name]
    start = 0.3 if name == "lj" else model.a0 + 1e-3  # LJ: beyond its force minimum at 0.252
    z = np.linspace(start, 3.0, 300)
    for f in (model(z, 0.0, False), kernel(model, z, 0.0, False)):
        assert np.all(f < 0.0)
        assert np.all(np.diff(f) > 0.0)  # |F| decreases with the gap


@pytest.mark.parametrize("name", [*CONTACT_MODELS, "lj"])
def test_contact_is_repulsive_and_stiffening(name: str) -> None:
    """Deep in contact the force pushes the tip away and grows with the indentation."""
    model = FORCE_MODELS[name]
    if name == "lj":
        z = np.linspace(0.19, 0.12, 50)  # inside the equilibrium gap (r / a)**(1/6) = 0.2
    else:
        z = model.a0 - np.linspace(0.01, 0.15, 50)
    contact = model.has_contact  # LJ has no contact branch: its wall is the z**-8 term
    for f in (model(z, 0.0, contact), kernel(model, z, 0.0, contact)):
        assert np.all(np.diff(f) > 0.0)  # dF/d delta > 0 (z decreasing)
        assert f[-1] > 0.0


@pytest.mark.parametrize("name", RATE_MODELS)
def test_rate_term_opposes_the_gap_velocity(name: str) -> None:
    model = FORCE_MODELS[name]
    z, _, contact = physical_points(model, seed=1)
    if name.startswith("visco"):  # the rate term lives only in contact, away from delta = 0
        keep = contact & (z < model.a0 - 1e-3)
        z, contact = z[keep], contact[keep]
    for zd in (0.5, -0.8):
        for f in (model, lambda a, b, c: kernel(model, a, b, c)):
            rate_part = f(z, zd, contact) - f(z, 0.0, contact)
            assert np.all(np.sign(rate_part) == -np.sign(zd))


@pytest.mark.parametrize("name", CONSERVATIVE)
def test_conservative_force_ignores_the_rate(name: str) -> None:
    model = FORCE_MODELS[name]
    z, zd, contact = physical_points(model, seed=2)
    np.testing.assert_array_equal(kernel(model, z, zd, contact), kernel(model, z, 0.0, contact))
    np.testing.assert_array_equal(model(z, zd, contact), model(z, 0.0, contact))


# ------------------------------------------------------------------ analytic limits
def test_sphere_vdw_limits() -> None:
    """Exact Hamaker sphere--plane: ``-H R/(6 z^2)`` for z << R, ``-2 H R^3/(3 z^4)`` for z >> R."""
    h, r = 2e-19, 20e-9
    m = SphereVdW.from_si(hamaker_j=h, tip_radius_m=r, scales=SCALES)
    for zr in (1e-3, 1e-4):
        z = zr * r
        ratio = float(m(z / SCALES.length)) * FORCE_UNIT / (-h * r / (6 * z**2))
        assert ratio == pytest.approx(1.0 - zr, abs=2 * zr**2)  # (1 + z/2R)**-2
    z = 1e3 * r
    ratio = float(m(z / SCALES.length)) * FORCE_UNIT / (-2 * h * r**3 / (3 * z**4))
    assert ratio == pytest.approx(1.0 - 4e-3, abs=2e-5)  # (1 + 2R/z)**-2


def test_hysteretic_jkr_closed_forms() -> None:
    """JKR: F(delta=0) = -4/3 pi w R, pull-off (load control) -3/2 pi w R, neck -5/6 pi w R,
    neck indentation -3/4 (pi^2 w^2 R / E*^2)^(1/3), zero-load radius^3 = 9 pi w R^2 / (2 E*)."""
    e, r, w, ell = 10e9, 10e-9, 0.05, SCALES.length
    m = FORCE_MODELS["jkr_hysteretic"]
    pw = math.pi * w * r / FORCE_UNIT
    a0 = m.a0
    assert a0 == pytest.approx(0.03, rel=1e-14)
    assert m.break_indentation * ell == pytest.approx(
        -0.75 * (math.pi**2 * w**2 * r / e**2) ** (1 / 3), rel=1e-12)
    for f in (lambda z: float(m(z, 0.0, True)), lambda z: float(kernel(m, z, 0.0, True))):
        assert f(a0) == pytest.approx(-4 / 3 * pw, rel=1e-10)
        assert f(a0 - m.break_indentation) == pytest.approx(-5 / 6 * pw, rel=1e-10)
        # minimum over the stable branch, by golden search on the indentation
        lo, hi = m.break_indentation, 0.0
        for _ in range(120):
            d1, d2 = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
            lo, hi = (lo, d2) if f(a0 - d1) < f(a0 - d2) else (d1, hi)
        assert f(a0 - lo) == pytest.approx(-1.5 * pw, rel=1e-10)
    # zero load: alpha a^3 = beta a^1.5  ->  a^3 = 9 pi w R^2 / (2 E*)
    a = (9 * math.pi * w * r**2 / (2 * e)) ** (1 / 3) / ell
    delta = a**2 / m.r_j - m.c_j * math.sqrt(a)
    assert float(m(a0 - delta, 0.0, True)) == pytest.approx(0.0, abs=1e-12 * pw)
    # the tail is continuous at formation: vdw / a0^2 = 4/3 pi w R
    assert m.vdw / a0**2 == pytest.approx(4 / 3 * pw, rel=1e-10)


def test_dmt_limits() -> None:
    """Adhesion (pull-off) ``vdw / a0^2``; deep contact ``stiffness delta^p`` dominates."""
    m = FORCE_MODELS["dmt"]
    assert float(m(m.a0, 0.0, True)) == pytest.approx(-m.vdw / m.a0**2, rel=1e-14)
    assert m.adhesion == pytest.approx(0.05, rel=1e-14)
    d = 0.1
    f = float(m(m.a0 - d, 0.0, True))
    assert f == pytest.approx(20.0 * d**1.5 - 0.05, rel=1e-14)


# ------------------------------------------------------------------ SI conversions (hand numbers)
def test_scales_units() -> None:
    assert SCALES.force == pytest.approx(4e-7, rel=1e-15)
    assert SCALES.energy == pytest.approx(4e-15, rel=1e-15)
    assert SCALES.omega0 == pytest.approx(1.884955592e6, rel=1e-9)
    assert SCALES.velocity == pytest.approx(1.884955592e-2, rel=1e-9)


def test_lennard_jones_from_si_chapter2() -> None:
    """Table 2.1: A1 = 1.35961e-70 J m^6, A2 = 1.8651e-19 J, R = 150 nm, k = 0.11, eta* = 6.542 nm.

    A2 R / (6 k L^3) = 2.797650e-26 / 1.847866e-25 = 0.1513972;
    A1 R / (180 k L^9) = 2.039415e-77 / 4.345729e-73 = 4.692946e-5.
    """
    sc = Scales(spring_constant=0.11, resonance_frequency=11.804e3, length=6.542e-9)
    m = LennardJones.from_si(a1_jm6=1.35961e-70, a2_j=1.8651e-19, tip_radius_m=150e-9, scales=sc)
    assert m.attraction == pytest.approx(0.1513972, rel=1e-6)
    assert m.repulsion == pytest.approx(4.692946e-5, rel=1e-6)


def test_contact_models_from_si() -> None:
    """H = 1e-19 J, R = 10 nm, E* = 1 GPa, a0 = 0.3 nm on k = 40 N/m, L_ref = 10 nm.

    vdw = H R / (6 k L^3) = 1e-27 / 2.4e-22 = 4.166667e-6;
    stiffness = 4/3 E* sqrt(R L) / k = 4/3 * 1e9 * 1e-8 / 40 = 0.3333333;
    Hertz force at 0.5 nm: 4/3 E* sqrt(R) d^1.5 = 1.490712e-9 N = 3.726780e-3 k L.
    """
    kw = {"tip_radius_m": 10e-9, "reduced_modulus_pa": 1e9, "a0_m": 0.3e-9, "scales": SCALES}
    d = DMT.from_si(hamaker_j=1e-19, **kw)
    assert (d.a0, d.exponent) == (pytest.approx(0.03, rel=1e-14), 1.5)
    assert d.vdw == pytest.approx(4.166667e-6, rel=1e-6)
    assert d.stiffness == pytest.approx(0.3333333, rel=1e-6)
    hertz = DMT.from_si(hamaker_j=0.0, **kw)
    assert float(hertz(0.03 - 0.05, 0.0)) == pytest.approx(3.726780e-3, rel=1e-6)
    # JKR (dissertation form): adhesion 3 pi R gamma = 4.712389e-9 N = 0.01178097 k L
    j = JKR.from_si(surface_energy_j_per_m2=0.05, **kw)
    assert j.vdw / j.a0**2 == pytest.approx(0.01178097, rel=1e-6)
    # viscosity 1e-3 N s / m^1.5, q = 0.5: c_v = eta L^0.5 omega0 / k = 4.712389e-3
    v = ViscoelasticDMT.from_si(hamaker_j=1e-19, viscosity_si=1e-3, **kw)
    assert v.viscosity == pytest.approx(4.712389e-3, rel=1e-6)
    assert (v.vdw, v.stiffness) == (d.vdw, d.stiffness)


@pytest.mark.parametrize("p", [1.0, 1.5, 2.0, 2.27, 3.0])
def test_contact_prefactor_has_the_units_of_a_force_for_every_exponent(p: float) -> None:
    """``(4/3) E* R**(2-p) delta**p`` is a force: at ``delta = R`` it is ``(4/3) E* R**2``.

    Halving every length (R, delta, a0, L_ref) must scale the force by 1/4 for every ``p``
    (E* * length**2); a prefactor with the wrong length power breaks this for ``p != 1.5``.
    """
    def force_n(scale: float) -> float:
        r, ell = 10e-9 * scale, 10e-9 * scale
        sc = Scales(spring_constant=40.0, resonance_frequency=3e5, length=ell)
        d = DMT.from_si(hamaker_j=0.0, tip_radius_m=r, reduced_modulus_pa=1e9,
                        a0_m=0.3e-9 * scale, exponent=p, scales=sc)
        delta = r  # indentation of one tip radius
        return float(d(d.a0 - delta / ell, 0.0)) * sc.spring_constant * ell

    assert force_n(1.0) == pytest.approx(4.0 / 3.0 * 1e9 * (10e-9) ** 2, rel=1e-9)
    assert force_n(0.5) == pytest.approx(force_n(1.0) / 4.0, rel=1e-9)


def test_long_range_models_from_si() -> None:
    # exponential damping 1e-7 N s/m: c = c_SI omega0 / k = 4.712389e-3; decay 2 nm -> 0.2
    e = ExponentialDamping.from_si(coefficient_ns_per_m=1e-7, decay_length_m=2e-9, scales=SCALES)
    assert (e.coefficient, e.decay_length) == (pytest.approx(4.712389e-3, rel=1e-6),
                                               pytest.approx(0.2, rel=1e-14))
    # electrostatic, 2 V, R = 10 nm, at z = R: pi eps0 R^2 V^2 / (z (z + R)) = 5.563e-11 N
    s = Electrostatic.from_si(voltage_v=2.0, tip_radius_m=10e-9, scales=SCALES)
    assert float(s(1.0)) == pytest.approx(-1.390813e-4, rel=1e-6)
    # sphere vdW, H = 1e-19, R = 10 nm: s = 2 H (R/L)^3 / (3 k L^2) = 1.666667e-5
    v = SphereVdW.from_si(hamaker_j=1e-19, tip_radius_m=10e-9, scales=SCALES)
    assert (v.strength, v.radius) == (pytest.approx(1.666667e-5, rel=1e-6), 1.0)


def test_hysteretic_jkr_from_si() -> None:
    """E* = 10 GPa, R = 10 nm, w = 0.05: alpha = 4 E* L^2 / (3 R k) = 3.333333,
    beta = sqrt(8 pi w E* L) / k = 0.2802496, c_j = sqrt(2 pi w / (E* L)) = 0.05604991."""
    m = FORCE_MODELS["jkr_hysteretic"]
    assert m.alpha == pytest.approx(3.333333, rel=1e-6)
    assert m.beta == pytest.approx(0.2802496, rel=1e-6)
    assert m.c_j == pytest.approx(0.05604991, rel=1e-6)
    assert m.r_j == pytest.approx(1.0, rel=1e-14)


# ------------------------------------------------------------------ invalid parameters
def _dmt(**kw):
    return DMT(**{**DMT_PARAMS, **kw})


def _hj(**kw):
    return HystereticJKR(**{"a0": 0.03, "alpha": 3.3, "beta": 0.28, "r_j": 1.0, "c_j": 0.056,
                            **kw})


SI = {"tip_radius_m": 10e-9, "reduced_modulus_pa": 1e9, "a0_m": 0.3e-9, "scales": SCALES}
INVALID = [
    ("a0", lambda: _dmt(a0=0.0)),
    ("a0", lambda: _dmt(a0=math.inf)),
    ("vdw", lambda: _dmt(vdw=-1e-3)),
    ("stiffness", lambda: _dmt(stiffness=0.0)),
    ("exponent", lambda: _dmt(exponent=0.5)),
    ("exponent", lambda: _dmt(exponent=math.nan)),
    ("viscosity", lambda: ViscoelasticDMT(**DMT_PARAMS, viscosity=-1.0)),
    ("viscosity_exponent", lambda: ViscoelasticDMT(**DMT_PARAMS, viscosity=1.0,
                                                   viscosity_exponent=3.0)),
    ("coefficient", lambda: ExponentialDamping(coefficient=-1.0, decay_length=0.2)),
    ("decay_length", lambda: ExponentialDamping(coefficient=1.0, decay_length=0.0)),
    ("repulsion", lambda: LennardJones(repulsion=-1.0, attraction=0.1)),
    ("attraction", lambda: LennardJones(repulsion=1e-6, attraction="strong")),
    ("strength", lambda: SphereVdW(strength=-1.0, radius=1.0)),
    ("radius", lambda: SphereVdW(strength=1.0, radius=0.0)),
    ("strength", lambda: Electrostatic(strength=-1.0, radius=1.0)),
    ("radius", lambda: Electrostatic(strength=1.0, radius=-1.0)),
    ("a0", lambda: JKR(a0=-0.1, vdw=0.1, stiffness=1.0)),
    ("alpha", lambda: _hj(alpha=0.0)),
    ("beta", lambda: _hj(beta=-1.0)),
    ("r_j", lambda: _hj(r_j=0.0)),
    ("c_j", lambda: _hj(c_j=math.inf)),
    ("vdw", lambda: _hj(vdw=-1.0)),
    ("vdw", lambda: _hj(alpha=50.0, beta=1.0, r_j=0.5, c_j=0.05)),  # repulsive at formation
    ("terms", lambda: ForceSum([])),
    ("terms", lambda: ForceSum([_dmt(), "dmt"])),
    ("terms", lambda: LennardJones(repulsion=1e-6, attraction=0.01) + _dmt()),
    ("terms", lambda: _hj() + LennardJones(repulsion=1e-6, attraction=0.01)),
    ("force", lambda: _dmt() + JKR(**DMT_PARAMS)),
    ("tip_radius_m", lambda: DMT.from_si(hamaker_j=1e-19, **{**SI, "tip_radius_m": 0.0})),
    ("reduced_modulus_pa", lambda: DMT.from_si(hamaker_j=1e-19,
                                               **{**SI, "reduced_modulus_pa": -1.0})),
    ("a0_m", lambda: DMT.from_si(hamaker_j=1e-19, **{**SI, "a0_m": 0.0})),
    ("hamaker_j", lambda: DMT.from_si(hamaker_j=-1e-19, **SI)),
    ("surface_energy_j_per_m2", lambda: JKR.from_si(surface_energy_j_per_m2=-1.0, **SI)),
    ("viscosity_si", lambda: ViscoelasticDMT.from_si(hamaker_j=1e-19, viscosity_si=-1.0, **SI)),
    ("work_of_adhesion_j_per_m2", lambda: HystereticJKR.from_si(
        reduced_modulus_pa=1e9, tip_radius_m=1e-8, work_of_adhesion_j_per_m2=0.0, a0_m=3e-10,
        scales=SCALES)),
    ("voltage_v", lambda: Electrostatic.from_si(voltage_v=1e5, tip_radius_m=1e-8,
                                                scales=SCALES)),
    ("decay_length_m", lambda: ExponentialDamping.from_si(coefficient_ns_per_m=1e-7,
                                                          decay_length_m=0.0, scales=SCALES)),
    ("length", lambda: Scales(spring_constant=40.0, resonance_frequency=3e5, length=0.0)),
]


@pytest.mark.parametrize(("param", "build"), INVALID,
                         ids=[f"{p}-{i}" for i, (p, _) in enumerate(INVALID)])
def test_invalid_parameters_raise_naming_the_parameter(param: str, build) -> None:
    with pytest.raises(ValueError, match=rf"^{param}\b"):
        build()


@pytest.mark.parametrize("kind, p1", [(Kind.INVERSE_POWER, 2.0), (Kind.SPHERE_ELECTROSTATIC, 3.0),
                                      (Kind.SPHERE_VDW, 1.5), (Kind.DETACHED_POWER, 2.0),
                                      (Kind.GAP_RATE, -1.0)])
def test_free_side_distance_terms_are_continued_past_the_contact_onset(kind, p1):
    """A trial RK4 stage can pass a contact switch not located yet: out of contact a distance
    term reads max(z, a0) there (bounded, continuous at a0), never z**-n near z = 0, which
    threw the tip through the sample in spectroscopy rows."""
    a0, zd = 0.025, -0.3
    at_a0 = term_value(int(kind), p1, 0.0, a0, a0, zd, 0.0, False, False)
    for z in (0.02, 1e-6, -0.01):
        assert term_value(int(kind), p1, 0.0, a0, z, zd, 0.0, False, False) == at_a0
    above = term_value(int(kind), p1, 0.0, a0, 2 * a0, zd, 0.0, False, False)
    assert math.isfinite(above) and above != at_a0  # the free side itself is unchanged
    kinds = np.array([int(Kind.INVERSE_POWER)])
    one = np.ones(1)
    assert law_force(kinds, 2 * one, 0 * one, -one, a0, -0.01, zd, 0.0, False, False) == \
        -(a0 ** -2.0)
