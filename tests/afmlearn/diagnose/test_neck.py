"""The diagnosis' JKR neck (``adhesion_hysteresis``) against the simulator's hysteretic JKR."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.diagnose._kernel import simulate_model, simulate_reference
from afmlearn.diagnose.hypotheses.adhesion_hysteresis import Neck, work_of_adhesion
from afmlearn.diagnose.model import DiagnosisModel
from afmlearn.diagnose.spec import ModelSpec
from simulator import Scales
from simulator.forces import HystereticJKR

SCALES = Scales(spring_constant=20.68, resonance_frequency=259.9e3, length=10e-9)


def _jkr(e_star: float, radius: float, w: float, a0: float) -> HystereticJKR:
    return HystereticJKR.from_si(reduced_modulus_pa=e_star, tip_radius_m=radius,
                                 work_of_adhesion_j_per_m2=w, a0_m=a0, scales=SCALES)


def _as_model(jkr: HystereticJKR, radius_m: float) -> DiagnosisModel:
    """The diagnosis model whose force is ``jkr``: tail at JKR continuity, no DMT contact
    term, the neck at the simulator's break distance with the JKR stiffness as coefficient."""
    brk = jkr.law().break_distance
    spec = ModelSpec(a0=jkr.a0, extensions=(Neck(length=brk, radius=radius_m / SCALES.length),))
    coef = np.array([1.0, 1 / 300, 0.02, -jkr.vdw, 0.0, jkr.alpha])
    return DiagnosisModel(spec=spec, coef=coef, omega=1.0, gap=1.0, scales=SCALES)


@pytest.mark.parametrize("e_star, radius, w, a0", [(1e9, 5e-9, 0.1, 0.2e-9),
                                                   (3e9, 15e-9, 0.2, 0.3e-9),
                                                   (5e9, 20e-9, 0.3, 0.4e-9)])
def test_neck_force_is_the_simulators_hysteretic_jkr(e_star, radius, w, a0):
    """Known answer: with the tail at JKR continuity and the JKR stiffness as the neck's
    coefficient, the model's force (columns and kernel encoding) is the simulator's
    HystereticJKR on every branch -- free, in contact, and on the neck up to its break --
    checked against the simulator's plain reference (a bracketing root per point)."""
    jkr = _jkr(e_star, radius, w, a0)
    m = _as_model(jkr, radius)
    neck = m.spec.neck
    assert neck.contact_constants() == pytest.approx((jkr.r_j, jkr.c_j), rel=1e-12)
    brk = neck.neck_length()
    z = np.linspace(jkr.a0 - 0.2, jkr.a0 + 2.0 * brk, 301)
    zd = np.zeros_like(z)
    for attached in (z <= jkr.a0 + brk, z <= jkr.a0):      # retraction / approach
        want = jkr._reference(z, zd, attached)
        got = m.force(z, zd, attached)
        assert np.allclose(got, want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want)))
    # the encoding the kernel integrates: the same force, term by term
    _, kinds, p1, p2, coefs, a0_, dc = m.kernel_args()
    assert dc == pytest.approx(brk) and a0_ == jkr.a0
    from simulator.forces._kernel import law_force
    for zi, att in [(jkr.a0 - 0.05, True), (jkr.a0 + 0.5 * brk, True),
                    (jkr.a0 + 0.5 * brk, False), (jkr.a0 + 3 * brk, False)]:
        f = law_force(kinds, p1, p2, coefs, jkr.a0, zi, 0.0, 0.0, zi <= jkr.a0, att)
        assert f == pytest.approx(float(jkr._reference(np.array([zi]), np.zeros(1),
                                                       np.array([att]))[0]), rel=1e-9)
    # the JKR pull: nonzero where contact forms (-4/3 pi w R), larger at the snap than the tail
    f0 = float(m.force(np.array([jkr.a0]), np.zeros(1), np.array([True]))[0])
    assert f0 * SCALES.force == pytest.approx(-4 / 3 * math.pi * w * radius, rel=1e-9)
    # and the work of adhesion read back from the fitted coefficient
    assert work_of_adhesion(m) == pytest.approx(w, rel=1e-9)


def test_neck_column_is_zero_where_contact_forms_and_nests_the_baseline():
    """The column vanishes at delta = 0 (continuity with the free branch) and is a pull on
    the neck; with a zero coefficient the kernel runs the baseline (no neck regime)."""
    neck = Neck(length=0.08, radius=1.2)
    a0 = 0.03
    z = np.array([a0, a0 + 0.04, a0 + 0.079])
    col = neck.column(z, np.ones(3, bool), a0)
    assert abs(col[0]) < 1e-12 and np.all(col[1:] < 0)
    spec = ModelSpec(a0=a0, extensions=(neck,))
    m = DiagnosisModel(spec=spec, coef=np.array([1.0, 1 / 300, 0.02, -5e-5, 2.0, 0.0]),
                       omega=1.0, gap=1.0, scales=SCALES)
    assert m.kernel_args()[-1] == 0.0


def test_jkr_neck_kernel_matches_reference_and_loses_the_loop_area():
    """The compiled run with a JKR neck equals its plain-Python twin, and on a periodic orbit
    the energy the sample takes per cycle is the area between the neck and the tail
    (drive input minus lever damping; quadrature of the column over the neck)."""
    from afmlearn.diagnose.output_error import periodic_orbit

    jkr = _jkr(2e9, 10e-9, 0.2, 0.3e-9)
    m = _as_model(jkr, 10e-9)
    args = m.kernel_args()
    s0 = np.array([0.9, 0.4, 0.0, 0.0])
    dt = 2 * math.pi / 200

    class _F:
        a0, dc = jkr.a0, args[-1]

        def __call__(self, z, zd, att):
            return float(m.force(np.array([z]), np.array([zd]), np.array([att]))[0])

    fast, _, _ = simulate_model(s0, False, 0.0, dt, 300, 2, *args)
    ref = simulate_reference(s0, False, 0.0, dt, 300, 2, args[0], _F())
    assert np.max(np.abs(fast - ref)) < 1e-10
    x, v = m.simulate(np.array([0.0, 2.7, 0.0, 0.0]), attached0=False, tau0=0.0, dtau=0.01,
                      n_samples=1, substeps=1, settle_periods=2000)
    x, v, ok = periodic_orbit(m, np.array([x[0], v[0], 0.0, 0.0]), False, n_out=4096)
    assert ok and np.min(1.0 - x) < jkr.a0                 # the orbit taps
    tau = np.arange(x.size) * 2 * math.pi / x.size
    e_ts = np.mean(m.coef[2] * np.cos(tau) * v - m.coef[1] * v**2) * 2 * math.pi
    dc = m.spec.neck.neck_length()
    zq = np.linspace(jkr.a0, jkr.a0 + dc, 20001)
    col = m.spec.neck.column(zq, np.ones(zq.size, bool), jkr.a0)
    area = -np.trapezoid(col, zq) * jkr.alpha
    assert area > 0 and e_ts == pytest.approx(area, rel=5e-3)


def _loop_area_j(alpha: float, neck: Neck, a0: float, scales: Scales) -> float:
    """Energy a neck takes per cycle that breaks it [J]: the area between the JKR pull and
    the tail from contact to the break, ``-alpha int theta dz``."""
    z = np.linspace(a0, a0 + neck.neck_length(), 20001)
    area = -alpha * np.trapezoid(neck.column(z, np.ones(z.size, bool), a0), z)
    return float(area) * scales.spring_constant * scales.length**2


@pytest.mark.slow
def test_constructed_jkr_neck_series_is_named_adhesion_hysteresis(tmp_path):
    """A hysteretic JKR series (the simulator's law; w = 0.2 J/m^2, 15 nm tip, E* 3 GPa, four
    tapping set-points, 1 % noise) diagnosed with every cause competing is named
    adhesion_hysteresis with a positive gain, and the fitted neck takes the true loop energy
    per cycle (within 25 %). The neck length itself is not identified at this noise: a long,
    soft neck takes the same energy (measured: free fit 2.2 nm, chi2 165.2; the drawn 0.65 nm
    refitted, 168.4; loop energy 0.0050 vs the truth's 0.0052 k L_ref^2)."""
    from afmlearn.diagnose import Diagnoser
    from afmlearn.diagnose.synthetic import SeriesCase, simulate_series
    from afmlearn.io import Experiment

    e_star, radius, w, a0 = 3e9, 15e-9, 0.2, 0.3e-9
    case = SeriesCase(causes=("adhesion_hysteresis",), quality_factor=250.0,
                      free_amplitude_m=20e-9, setpoints=(0.45, 0.4, 0.35, 0.3),
                      settle_offsets=(0.1, 0.4, 0.7, 0.9), tip_radius_m=radius, hamaker_j=1e-19,
                      reduced_modulus_pa=e_star, a0_m=a0,
                      effects={"adhesion_hysteresis": {"work_of_adhesion_j_per_m2": w}}, seed=5)
    path = tmp_path / "series.h5"
    simulate_series(case, path, n_periods=20, noise_level=0.01)
    dg = Diagnoser().fit(Experiment.read(path))
    assert dg.cause_ == "adhesion_hysteresis", [(c.cause, c.delta_chi2, c.gain)
                                                for c in dg.candidates_]
    assert dg.gain_ > 0.05
    m = dg.extended_
    fitted = _loop_area_j(float(m.force_coefficients[-1]), m.spec.get(Neck), m.spec.a0,
                          m.scales)
    jkr = _jkr(e_star, radius, w, a0)
    truth = _loop_area_j(jkr.alpha, Neck(jkr.law().break_distance, jkr.r_j), jkr.a0, SCALES)
    assert fitted == pytest.approx(truth, rel=0.25)


#: seed-2026 development draw 0 of the benchmark's hidden-neck series (8 set-points, 200
#: samples/period, 1 % noise, 30 periods; not an evaluation draw)
_DEV_NECK_0 = dict(
    causes=("adhesion_hysteresis",), quality_factor=189.66452595467518,
    free_amplitude_m=1.9293376565300568e-08,
    setpoints=(0.9049329056271254, 0.8273189628791634, 0.7352516982990762, 0.6592309724116246,
               0.5816806009280548, 0.5217505580636531, 0.4189736030189014,
               0.34179741181841455),
    settle_offsets=(0.6604356016971168, 0.48324353719640334, 0.42586362753841467,
                    0.8890562134951094, 0.9382807045345221, 0.7526125215203732,
                    0.3324654789702688, 0.738551344873965),
    tip_radius_m=1.637089357898396e-08, hamaker_j=1.1639712623333508e-19,
    reduced_modulus_pa=3067285065.3104353, a0_m=3.0594558652132964e-10,
    effects={"adhesion_hysteresis": {"work_of_adhesion_j_per_m2": 0.20849022802706235}},
    seed=1582017597)


@pytest.mark.slow
def test_neck_fit_reaches_the_drawn_laws_basin_on_a_series(tmp_path):
    """On a hidden-neck series the fitted neck ends no higher than the drawn law refitted
    (its neck length and the tip radius pinned, everything else fitted, same evaluations).
    Session 8's starts left the neck's 10 joint evaluations short on this draw (chi2 387.6
    against the drawn law's 372.7: the neck's snap makes the residual non-smooth), so the
    neck lost a tie it should share; ``min_refine_nfev`` gives it 20."""
    from typing import final

    from afmlearn.diagnose import Diagnoser
    from afmlearn.diagnose.hypotheses import AdhesionHysteresis
    from afmlearn.diagnose.hypotheses.base import AbstractHypothesis, Parameter
    from afmlearn.diagnose.synthetic import SeriesCase, simulate_series
    from afmlearn.io import Experiment

    case = SeriesCase(**_DEV_NECK_0)
    path = tmp_path / "neck.h5"
    simulate_series(case, path, samples_per_period=200, n_periods=30.0, noise_level=0.01)
    w = case.effects["adhesion_hysteresis"]["work_of_adhesion_j_per_m2"]
    jkr = HystereticJKR.from_si(reduced_modulus_pa=case.reduced_modulus_pa,
                                tip_radius_m=case.tip_radius_m, work_of_adhesion_j_per_m2=w,
                                a0_m=case.a0_m, scales=SCALES)
    drawn_m = jkr.law().break_distance * SCALES.length
    free = AdhesionHysteresis()

    @final
    class Pinned(AbstractHypothesis):
        """The neck with its length held at the drawn one."""

        cause = free.cause
        n_starts, output_error_scan = free.n_starts, free.output_error_scan
        refine_both_starts = free.refine_both_starts
        min_refine_nfev = free.min_refine_nfev

        def parameters(self, ctx):
            v = drawn_m / ctx.length_m
            return [Parameter("neck_length", v * (1 - 1e-6), v * (1 + 1e-6), (v,), log=True),
                    free.parameters(ctx)[1]]

        def extend(self, spec, values):
            return free.extend(spec, values)

    def chi2(h: AbstractHypothesis) -> float:
        dg = Diagnoser(hypotheses=[h], max_causes=1, screen_chi2=0.0).fit(Experiment.read(path))
        return float(dg.candidates_[0].chi2)

    fitted, drawn = chi2(free), chi2(Pinned())
    assert fitted <= drawn + 1.0, (fitted, drawn)
