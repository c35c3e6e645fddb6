"""One model over many observations: phases projected out, observations in common units,
held-out folds, coefficient embedding of nested structures."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from afmlearn.diagnose.balance import HarmonicBalance, to_real
from afmlearn.diagnose.hypotheses import ElectrostaticTerm, Neck, ViscoelasticTerm
from afmlearn.diagnose.joint import JointBalance, wrap
from afmlearn.diagnose.observation import as_traces, build_observations, folds
from afmlearn.diagnose.output_error import align_phase
from afmlearn.diagnose.spec import ModelSpec
from afmlearn.io import Experiment, Trace, read_trace


def test_align_phase_recovers_a_delay_and_weighs_the_prior():
    rng = np.random.default_rng(5)
    n = np.arange(21)
    X0 = (rng.normal(size=21) + 1j * rng.normal(size=21)) / (1 + n) ** 2
    X0[0] = 0.3
    for phi in (-2.9, -0.4, 0.0, 1.3, 3.1):
        sigma = 1e-4
        Y = X0 * np.exp(-1j * n * phi) + sigma * (rng.normal(size=21) + 1j * rng.normal(size=21))
        assert abs(wrap(align_phase(X0, Y, sigma) - phi)) < 1e-3
    # a tight prior wins against weak data; a loose one does not move the answer
    Y = X0 * np.exp(-1j * n * 0.5)
    assert abs(align_phase(X0, Y, 1.0, (0.9, 1e-4)) - 0.9) < 1e-3
    assert abs(align_phase(X0, Y, 1e-6, (0.9, 10.0)) - 0.5) < 1e-6


def test_folds_hold_every_observation_out_once():
    gaps = [5.0, 1.0, 3.0, 2.0, 4.0, 0.5, 2.5, 3.5]
    loo = folds(gaps[:4], 4)
    assert loo == [[1], [3], [2], [0]]                 # one each, in gap order
    k = folds(gaps, 4)
    assert sorted(j for f in k for j in f) == list(range(8)) and len(k) == 4
    median = float(np.median(gaps))
    for f in k:                                        # each fold spans the gap range
        g = sorted(gaps[j] for j in f)
        assert g[0] < median < g[-1]


def test_embed_places_nested_coefficients_by_feature():
    base = ModelSpec(a0=0.03, extensions=(ElectrostaticTerm(radius=0.5),))
    ext = base.with_extension(ViscoelasticTerm(exponent=0.5)).with_extension(Neck(length=0.1))
    coef = np.array([1.0, 0.003, 0.004, -1e-4, 2.0, -3e-3])       # K D B vdw contact elec
    out = ext.embed(base, coef)
    keys = ext.term_keys()
    assert keys == ["vdw", "contact", "visco", "electrostatic", "neck"]
    assert out.size == 3 + len(keys)
    assert out[3 + keys.index("electrostatic")] == -3e-3
    assert out[3 + keys.index("visco")] == 0.0 and out[3 + keys.index("neck")] == 0.0
    assert np.array_equal(out[:5], coef[:5])


def test_restrict_inverts_embed_with_further_drive_amplitudes():
    """The backward check restricts the final model's coefficients to a nested spec."""
    base = ModelSpec(a0=0.03, extensions=(ElectrostaticTerm(radius=0.5),))
    ext = base.with_extension(ViscoelasticTerm(exponent=0.5)).with_extension(Neck(length=0.1))
    coef = np.array([1.0, 0.003, 0.004, -1e-4, 2.0, -3e-3, 0.005])   # ... elec, 2nd drive
    full = ext.embed(base, coef)
    full[3 + ext.term_keys().index("visco")] = 7.0                   # dropped by restrict
    assert np.array_equal(base.restrict(ext, full), coef)
    assert full[-1] == 0.005


@pytest.fixture(scope="module")
def series(make_series):
    path, case = make_series("none", 3)
    return read_trace(path), case


def test_observations_share_one_length_and_keep_the_recorded_phase(series):
    trace, _ = series
    warnings: list[str] = []
    obs = build_observations(as_traces(Experiment.from_trace(trace)), phase_sd=0.02,
                             window_periods=20.0, max_windows=8, warnings=warnings)
    assert len(obs) == trace.n_points and {o.kind for o in obs} == {"steady"}
    length = obs[0].cal.scales.length
    assert math.isclose(length, float(np.mean(trace.gap_m)), rel_tol=1e-12)
    for i, o in enumerate(obs):
        assert o.cal.scales.length == length
        assert np.allclose(o.x * length, trace.deflection_m[i], rtol=1e-12, atol=0.0)
        assert math.isclose(o.gap_m, float(trace.gap_m[i]), rel_tol=1e-12)
        # model convention B cos(Omega tau - phi): phi = -drive_phase_rad
        assert o.phase_prior == (-float(trace.drive_phase_rad[i]), 0.02)


def test_a_ramp_becomes_quasi_steady_windows(series):
    trace, _ = series
    rows = [trace.row(i) for i in range(trace.n_points)]
    y = np.concatenate([r.deflection_m for r in rows])
    gap = np.concatenate([np.full(r.deflection_m.size, float(r.gap_m)) for r in rows])
    ramp = Trace(y, **{**rows[0].metadata(), "gap_m": gap, "drive_phase_rad": None})
    warnings: list[str] = []
    obs = build_observations([ramp], phase_sd=0.02, window_periods=10.0, max_windows=8,
                             warnings=warnings)
    assert {o.kind for o in obs} == {"ramp_window"} and len(obs) == 8
    # two windows per 20-period row, each at its row's gap
    got = sorted({round(o.gap_m * 1e12) for o in obs})
    assert got == sorted({round(float(g) * 1e12) for g in trace.gap_m})
    assert any("ramp moves the gap" in w for w in warnings)     # steps: not quasi-static


def test_projected_phase_is_the_exact_minimum(series):
    trace, _ = series
    obs = build_observations(as_traces(trace), phase_sd=0.02, window_periods=20.0,
                             max_windows=8, warnings=[])
    from afmlearn.diagnose.balance import PeriodicOrbit
    from afmlearn.preprocess import fit_harmonics
    hbs = []
    for o in obs:
        hf = fit_harmonics(o.tau, o.x, o.cal.omega, n_harmonics=20)
        hbs.append(HarmonicBalance(PeriodicOrbit(hf, gap=o.gap, quality_factor=o.cal.quality_factor,
                                                 drive_amplitude=o.cal.drive_amplitude)))
    jb = JointBalance(hbs, [None] * len(hbs))                  # phases not recorded
    spec = ModelSpec(a0=0.3e-9 / obs[0].cal.scales.length)
    ph0 = jb.initial_phases(spec)
    sol = jb.solve(spec, ph0)
    for i, hb in enumerate(hbs):
        best = jb.best_phase(i, spec, sol.coef, ph0[i] + 1.0)
        grid = ph0[i] + np.linspace(-np.pi, np.pi, 20001)

        def block(ph: float, hb=hb) -> float:
            A, b = hb.design(spec, ph)
            r = A @ sol.coef - b
            return float(r @ r)

        brute = grid[int(np.argmin([block(g) for g in grid]))]
        assert abs(wrap(best - brute)) < 1e-3
        assert block(best) <= block(brute) + 1e-9
    # alternating with the linear solve never increases the chi-square
    proj = jb.solve(spec, ph0, project=3)
    assert proj.chi2 <= sol.chi2 + 1e-9
    # the recorded phases (as priors) agree with the fitted ones: the law is the truth's
    rec = [o.phase_prior[0] for o in obs]
    assert max(abs(wrap(p - r)) for p, r in zip(proj.phases, rec, strict=True)) < 0.2
    assert np.all(np.isfinite(to_real(hbs[0].orbit.Y)))


def _balances(traces, *, shift: tuple[int, int] | None = None) -> list[HarmonicBalance]:
    """Harmonic balances (lever whitening) of 1-D records; ``shift = (row, m)`` rolls that
    row's samples by ``m`` (a pure delay of its drive phase by ``m`` samples)."""
    from afmlearn.diagnose.balance import PeriodicOrbit
    from afmlearn.preprocess import fit_harmonics
    obs = build_observations(traces, phase_sd=0.02, window_periods=20.0, max_windows=8,
                             warnings=[])
    out = []
    for i, o in enumerate(obs):
        x = np.roll(o.x, -shift[1]) if shift is not None and shift[0] == i else o.x
        hf = fit_harmonics(o.tau, x, o.cal.omega, n_harmonics=20)
        out.append(HarmonicBalance(PeriodicOrbit(hf, gap=o.gap,
                                                 quality_factor=o.cal.quality_factor,
                                                 drive_amplitude=o.cal.drive_amplitude)))
    return out


def test_unrecorded_phases_reach_the_joint_minimum(series):
    """Without recorded phases the projected solve is the joint minimum over the phases (a
    plain reference: scipy least squares over the phases, coefficients solved inside), not
    where alternating the linear solve with each phase's minimum stalls; and the baseline
    then fits at least as well as with the recorded phases as priors (fewer constraints).
    Measured before the fix on a null 8-set-point series: 10,265 without vs 286 with."""
    from scipy.optimize import least_squares

    from afmlearn.diagnose.fit import fit_baseline
    from afmlearn.diagnose.hypotheses import Context
    trace, _ = series
    free = [dataclasses.replace(t, drive_phase_rad=None) for t in as_traces(trace)]
    jb = JointBalance(_balances(free), [None] * trace.n_points)
    length = float(np.mean(trace.gap_m))
    spec = ModelSpec(a0=0.3e-9 / length)
    ph0 = jb.initial_phases(spec)
    proj = jb.solve(spec, ph0, project=3)
    ref = least_squares(lambda p: jb.solve(spec, p).residual, np.array(ph0), method="trf",
                        x_scale="jac", diff_step=1e-7, xtol=1e-12, ftol=1e-12)
    chi2_ref = float(ref.fun @ ref.fun)
    assert proj.chi2 <= chi2_ref * (1 + 1e-6)
    assert max(abs(wrap(p - r)) for p, r in zip(proj.phases, ref.x, strict=True)) < 1e-3
    # the baseline over a0 (same data, phases recorded as priors vs not)
    rec = build_observations(as_traces(trace), phase_sd=0.02, window_periods=20.0,
                             max_windows=8, warnings=[])
    jb_rec = JointBalance(_balances(as_traces(trace)), [o.phase_prior for o in rec])
    zs = [hb.orbit.gap - hb.orbit.y for hb in jb.balances]
    ctx = Context(length_m=length, amplitude=float(abs(jb.balances[0].orbit.Y[1])),
                  z_min=float(min(z.min() for z in zs)), z_max=float(max(z.max() for z in zs)),
                  tip_radius=10e-9 / length, a0_max=3e-9 / length)
    with_phase = fit_baseline(jb_rec, ctx)
    without = fit_baseline(jb, ctx)
    assert without.chi2 <= with_phase.chi2 + 1e-6 * with_phase.chi2


def test_a_pure_phase_shift_of_a_row_is_absorbed_exactly(series):
    """Rolling one steady row by m samples delays its drive phase by 2 pi m / spp and changes
    nothing else: the fitted phase of that row moves by exactly that, the other phases, the
    coefficients and the chi-square stay (phases not recorded)."""
    trace, _ = series
    free = [dataclasses.replace(t, drive_phase_rad=None) for t in as_traces(trace)]
    ratio = trace.sample_rate_hz / float(np.atleast_1d(trace.drive_frequency_hz)[0])
    spp = round(ratio)
    assert abs(ratio - spp) < 1e-9 and free[2].deflection_m.size % spp == 0
    spec = ModelSpec(a0=0.3e-9 / float(np.mean(trace.gap_m)))
    jb = JointBalance(_balances(free), [None] * trace.n_points)
    # 25 of 200 samples: an eighth of a period, also a whole number of points of the force
    # grid (4096 per period), so the columns are rotated exactly too (37 samples: 1.7e-6)
    m = 25
    shifted = JointBalance(_balances(free, shift=(2, m)), [None] * trace.n_points)
    a = jb.solve(spec, jb.initial_phases(spec), project=3)
    b = shifted.solve(spec, shifted.initial_phases(spec), project=3)
    delta = 2 * math.pi * m / spp
    assert b.chi2 == pytest.approx(a.chi2, rel=1e-9)
    assert abs(wrap(b.phases[2] - (a.phases[2] - delta))) < 1e-5
    others = [k for k in range(trace.n_points) if k != 2]
    assert max(abs(wrap(b.phases[k] - a.phases[k])) for k in others) < 1e-5
    assert np.allclose(b.coef, a.coef, rtol=1e-5, atol=1e-12 * float(np.max(np.abs(a.coef))))
