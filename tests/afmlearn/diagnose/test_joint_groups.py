"""Several free amplitudes: one drive amplitude ``B`` per drive group, in the joint balance,
the output error and the held-out folds; one group is the one-``B`` problem bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.diagnose.balance import HarmonicBalance, PeriodicOrbit, bounded_lstsq
from afmlearn.diagnose.joint import JointBalance
from afmlearn.diagnose.output_error import OutputError
from afmlearn.diagnose.spec import ModelSpec
from afmlearn.preprocess import fit_harmonics
from simulator import Scales

Q = 300.0
OMEGA = 0.98         # below resonance: K (prior 1e-3) does not trade with B
GAP = 3.0            # far from the sample: the orbits are the free lever's (no contact)
NOISE = 1e-4
SCALES = Scales(spring_constant=20.0, resonance_frequency=3e5, length=10e-9)


def _lever_gain() -> float:
    """``|K - Omega^2 + i Omega D|`` of the calibrated lever (``B = gain * amplitude``)."""
    return abs(1.0 - OMEGA**2 + 1j * OMEGA / Q)


def _free_orbit(rng, amplitude: float, phase: float, prior: float) -> PeriodicOrbit:
    """The steady free orbit ``x = A cos(Omega tau - phase - lag)`` with white noise, its
    calibration prior ``F_c = prior`` (not necessarily the truth)."""
    lag = math.atan2(OMEGA / Q, 1.0 - OMEGA**2)
    tau = np.arange(40 * 200) * (2 * np.pi / OMEGA) / 200
    x = amplitude * np.cos(OMEGA * tau - phase - lag) + NOISE * rng.normal(size=tau.size)
    hf = fit_harmonics(tau, x, OMEGA, n_harmonics=8)
    return PeriodicOrbit(hf, gap=GAP, quality_factor=Q, drive_amplitude=prior, grid=512)


@pytest.fixture(scope="module")
def two_amplitudes():
    """Four free orbits: two at amplitude 0.5 (group 0), two at 1.5 (group 1). Group 1's
    calibration prior is 8 % off its true drive, which the data must correct. (Group 0's is
    true: on a free orbit at one frequency the drive and the lever's transfer function
    trade off along one direction, ``B_g |K - Omega^2 + i Omega D|^-1`` fixed; the data fix
    the ratio of the drives.)"""
    rng = np.random.default_rng(11)
    amps = [0.5, 1.5, 0.5, 1.5]
    groups = [0, 1, 0, 1]
    phases = [0.3, -1.2, 2.0, 0.9]
    true_b = [a * _lever_gain() for a in amps]
    prior = {0: true_b[0], 1: 0.92 * true_b[1]}
    hbs = [HarmonicBalance(_free_orbit(rng, a, ph, prior[g]))
           for a, ph, g in zip(amps, phases, groups, strict=True)]
    return hbs, groups, phases, true_b


def _reference_solve(hbs, groups, spec, phases):
    """Plain reference: the columns ``[K, D, B_0, c.., B_1]`` written out by hand."""
    blocks = [hb.design(spec, ph) for hb, ph in zip(hbs, phases, strict=True)]
    rows = []
    for (a, _), g in zip(blocks, groups, strict=True):
        full = np.zeros((a.shape[0], a.shape[1] + 1))
        full[:, :a.shape[1]] = a
        if g == 1:
            full[:, -1], full[:, 2] = a[:, 2], 0.0
        rows.append(full)
    A = np.vstack(rows)
    b = np.concatenate([bb for _, bb in blocks])
    p = A.shape[1]
    hb0, hb1 = hbs[groups.index(0)], hbs[groups.index(1)]
    fc0, fc1 = hb0.orbit.drive_amplitude, hb1.orbit.drive_amplitude
    rel = hb0.prior_rel
    P = np.zeros((4, p))
    P[0, 0] = 1 / hb0.stiffness_prior
    P[1, 1] = Q / rel
    P[2, 2] = 1 / (rel * fc0)
    P[3, p - 1] = 1 / (rel * fc1)
    t = np.array([1 / hb0.stiffness_prior, 1 / rel, 1 / rel, 1 / rel])
    lo0, hi0 = hb0.bounds(spec)
    lo = np.append(lo0, fc1 * (1 - hb0.box_rel))
    hi = np.append(hi0, fc1 * (1 + hb0.box_rel))
    lo[2], hi[2] = fc0 * (1 - hb0.box_rel), fc0 * (1 + hb0.box_rel)
    return bounded_lstsq(A, b, P, t, lo, hi)


def test_one_group_is_the_one_drive_problem_bit_for_bit(two_amplitudes):
    hbs, _, phases, _ = two_amplitudes
    hbs = hbs[::2]                      # the two orbits of group 0
    spec = ModelSpec(a0=0.03)
    ph = phases[::2]
    # the one-drive solve as it was written before drive groups existed
    blocks = [hb.design(spec, p) for hb, p in zip(hbs, ph, strict=True)]
    A = np.vstack([a for a, _ in blocks])
    b = np.concatenate([bb for _, bb in blocks])
    coef, r = bounded_lstsq(A, b, *hbs[0].prior_rows(A.shape[1]), *hbs[0].bounds(spec))
    for jb in (JointBalance(hbs, [None, None]), JointBalance(hbs, [None, None], groups=[0, 0])):
        sol = jb.solve(spec, ph)
        assert np.array_equal(sol.coef, coef) and np.array_equal(sol.residual, r)
        assert np.array_equal(jb.observation_coef(1, spec, sol.coef), coef)


def test_each_group_gets_its_own_drive(two_amplitudes):
    hbs, groups, phases, true_b = two_amplitudes
    spec = ModelSpec(a0=0.03)
    jb = JointBalance(hbs, [None] * 4, groups=groups)
    sol = jb.solve(spec, phases)
    n_force = spec.n_force
    assert sol.coef.size == 3 + n_force + 1
    coef_ref, r_ref = _reference_solve(hbs, groups, spec, phases)
    assert np.allclose(sol.coef, coef_ref, rtol=1e-10, atol=1e-14)
    assert np.allclose(sol.residual, r_ref, rtol=1e-10, atol=1e-12)
    # known answer: B_1 / B_0 = the ratio of the free amplitudes, 3 (not the 8 %-off prior's
    # 2.76); their common scale trades with K (0.1 % prior) and D along the one direction
    # the free orbits leave open, so it is the priors' compromise (within ~2 %)
    b0, b1 = sol.coef[2], sol.coef[3 + n_force]
    assert abs(b1 / b0 - 3.0) < 1e-3
    assert abs(b0 / true_b[0] - 1) < 0.02 and abs(b1 / true_b[1] - 1) < 0.02
    for i in range(4):
        assert jb.observation_coef(i, spec, sol.coef)[2] == (b0 if groups[i] == 0 else b1)
    # the free orbits need no force: the far-field columns stay near zero
    assert np.all(np.abs(sol.coef[3:3 + n_force]) < 1e-3)
    # data + 4 calibration rows: chi2 near rows - parameters; one shared B cannot fit the
    # two amplitudes (a factor 3 apart, one box of +-15 %)
    rows = sum(2 * hb.orbit.n_h + 1 for hb in hbs)
    assert sol.chi2 < rows + 6 * math.sqrt(2 * rows)
    one = JointBalance(hbs, [None] * 4).solve(spec, phases)
    assert one.chi2 > 1e3 * sol.chi2
    # the projected phases are the true ones up to one common shift (which trades with the
    # lever's lag, i.e. with D)
    proj = jb.solve(spec, [p + 0.2 for p in phases], project=3)
    shift = np.asarray(proj.phases) - phases
    assert np.ptp(shift) < 1e-3 and abs(float(np.mean(shift))) < 0.02


def test_a_held_out_group_keeps_its_calibrated_drive(two_amplitudes):
    """A fold without any row of a group keeps the layout; that group's drive is its
    calibration prior (how a whole held-out free amplitude is predicted)."""
    hbs, groups, phases, _ = two_amplitudes
    spec = ModelSpec(a0=0.03)
    jb = JointBalance(hbs, [None] * 4, groups=groups)
    sub = jb.subset([0, 2])
    assert sub.groups == [0, 0] and sub.n_groups == 2
    sol = sub.solve(spec, [phases[0], phases[2]])
    fc1 = hbs[1].orbit.drive_amplitude
    assert sol.coef.size == 3 + spec.n_force + 1
    assert abs(sol.coef[-1] / fc1 - 1) < 1e-9
    # the held-out group's observation is modelled with that drive
    oe = OutputError(jb, SCALES)
    assert oe.model(1, spec, sol.coef).coef[2] == sol.coef[-1]
    assert oe.model(0, spec, sol.coef).coef[2] == sol.coef[2]


def test_output_error_fits_each_group_with_its_drive(two_amplitudes):
    """The output-error stage simulates each observation with its group's ``B``: at the
    equation-error fit the model's own orbits match all four records (chi2 ~ rows)."""
    hbs, groups, phases, true_b = two_amplitudes
    spec = ModelSpec(a0=0.03)
    jb = JointBalance(hbs, [None] * 4, groups=groups)
    sol = jb.solve(spec, phases)
    oe = OutputError(jb, SCALES, n_out=128)
    r, ok, ph = oe.residual(spec, sol.coef)
    rows = sum(2 * hb.orbit.n_h + 1 for hb in hbs)
    assert ok and float(r @ r) < rows + 6 * math.sqrt(2 * rows)
    # swapping the two groups' drives makes every orbit wrong by a factor 3
    swapped = sol.coef.copy()
    swapped[2], swapped[-1] = sol.coef[-1], sol.coef[2]
    r2, _, _ = oe.residual(spec, swapped)
    assert float(r2 @ r2) > 1e4 * float(r @ r)
    refined, ok = oe.refine(sol, lambda v: spec, [], max_nfev=10)
    assert ok and refined.chi2 <= float(r @ r) + 1e-9
    assert abs(refined.coef[-1] / refined.coef[2] - 3.0) < 1e-3
