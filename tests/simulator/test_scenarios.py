"""Scenarios: physics of the protocols (not only shapes)."""

import math

import numpy as np
import pytest

from simulator import (
    RK4,
    Approach,
    BaseExcitation,
    Cantilever,
    SteadyState,
    Sweep,
    System,
    TipExcitation,
    Transient,
)
from simulator.forces import DMT, NoInteraction, ViscoelasticDMT
from simulator.labels import lock_in


@pytest.fixture(scope="module")
def cl1():
    return Cantilever.rectangular(n_modes=1, quality_factor=100)


def tapping(cl, force=None, ratio=1.5):
    force = force or DMT(a0=0.2, vdw=0.2**2 * 0.05, stiffness=20.0)
    return System(cl, force, TipExcitation.for_free_amplitude(cl, 1.0, ratio))


def test_steady_free_matches_linear_response(cl1):
    s = System(cl1, NoInteraction(), TipExcitation(amplitude=0.01))
    r = SteadyState(omega=0.97, n_periods=20, settle_periods=0).run(s)
    z = lock_in(r.deflection, r.phase)
    ref = s.excitation.free_response(cl1, 0.97).sum()
    assert abs(z - ref) / abs(ref) < 1e-6
    assert r.labels["regime"] == "free"
    assert r.labels["contact_fraction"] == 0.0


def test_steady_reaches_repulsive_branch(cl1):
    """Starting on the free orbit (amplitude 1.5 > gap) lands on the tapping branch."""
    r = SteadyState(omega=1.0, n_periods=20).run(tapping(cl1))
    lab = r.labels
    assert lab["regime"] == "repulsive"
    assert 0.0 < lab["contact_fraction"] < 0.5
    # amplitude limited by the surface: slightly less than the rest gap minus a0 ... plus
    # indentation; certainly far below the free amplitude 1.5
    assert 0.7 < lab["amplitude"] < 1.0
    assert lab["min_gap"] < 0.2  # indents the sample
    # conservative DMT: no energy into the sample
    assert abs(lab["dissipated_energy"]) < 1e-4 * lab["drive_energy"]
    # drive power balances cantilever damping in steady state (conservative force)
    w = r.labels["drive_energy"]
    assert w > 0


def test_viscoelastic_dissipates_and_balances(cl1):
    f = ViscoelasticDMT(a0=0.2, vdw=0.002, stiffness=20.0, viscosity=2.0)
    r = SteadyState(omega=1.0, n_periods=30, record_velocity=True,
                    samples_per_period=1000).run(tapping(cl1, f))
    lab = r.labels
    assert lab["dissipated_energy"] > 1e-3 * lab["drive_energy"]
    # independent check from samples: -oint F dz over whole periods
    v = r.velocity.sum(axis=0)
    zdot = -v
    spp = 2 * math.pi / (1.0 * r.dt)
    n = int(round(30 * spp))
    e_samples = -np.trapezoid(r.force[:n] * zdot[:n], dx=r.dt) / 30
    assert e_samples == pytest.approx(lab["dissipated_energy"], rel=2e-3)


def test_transient_step_changes_amplitude(cl1):
    r = Transient(omega=1.0, gap=1.0, step=-0.3, periods_before=10, periods_after=300).run(
        tapping(cl1))
    k = r.meta["step_index"]
    spp = int(round(2 * math.pi / r.dt))
    before = np.ptp(r.deflection[:k]) / 2
    after = np.ptp(r.deflection[-5 * spp:]) / 2
    # the surface came 0.3 closer: the tapping amplitude shrinks by about that much
    assert before - after == pytest.approx(0.3, abs=0.06)
    assert np.all(r.rest_gap[:k] == 1.0) and np.allclose(r.rest_gap[k:], 0.7)


def test_approach_amplitude_distance_curve(cl1):
    r = Approach(omega=1.0, gap_start=2.5, gap_end=0.6, n_periods=800,
                 samples_per_period=100).run(tapping(cl1))
    spp = 100
    amp = np.array([np.ptp(r.deflection[i:i + spp]) / 2
                    for i in range(0, r.deflection.size - spp, spp)])
    gap = r.rest_gap[::spp][: amp.size]
    far = gap > 2.0
    near = gap < 1.0
    assert amp[far].mean() == pytest.approx(1.5, rel=0.05)  # free amplitude far away
    assert amp[near].mean() < 1.1  # amplitude reduced by the surface
    assert np.all(np.diff(r.rest_gap) < 0)


def test_sweep_rows_continue_and_directions():
    cl = Cantilever.rectangular(n_modes=1, quality_factor=50)
    s = System(cl, NoInteraction(), TipExcitation(amplitude=0.02))
    sw = Sweep(omega_start=0.9, omega_stop=1.1, n_points=5, samples_per_point=2000,
               samples_per_period=100, direction="both", settle_periods=200)
    r = sw.run(s)
    assert r.q.shape == (10, 1, 2000)
    np.testing.assert_allclose(r.omega[:5], np.linspace(0.9, 1.1, 5))
    np.testing.assert_allclose(r.omega[5:], np.linspace(1.1, 0.9, 5))
    # forward and reverse agree for a linear oscillator once settled (same frequency)
    a = r.labels["amplitude"]
    assert a[2] == pytest.approx(a[7], rel=0.05)
    # continuity: row k+1 starts where row k ended (deflection is smooth across rows)
    step = abs(r.deflection[1, 0] - r.deflection[0, -1])
    typical = np.max(np.abs(np.diff(r.deflection[0])))
    assert step < 3 * typical


def test_sweep_streaming_equals_run():
    cl = Cantilever.rectangular(n_modes=2, quality_factor=50)
    s = System(cl, DMT(a0=0.2, vdw=0.002, stiffness=10.0), BaseExcitation(amplitude=0.02))
    sw = Sweep(omega_start=0.95, omega_stop=1.05, n_points=3, samples_per_point=500,
               samples_per_period=100, direction="forward", settle_periods=20)
    rows = {p.row: p.q.copy() for p in sw.iter_points(s)}
    r = sw.run(s)
    for k, q in rows.items():
        np.testing.assert_array_equal(q, r.q[k])


@pytest.mark.parametrize(
    ("cls", "kwargs", "name"),
    [
        (SteadyState, {"omega": -1.0}, "omega"),
        (SteadyState, {"n_periods": 0}, "n_periods"),
        (SteadyState, {"samples_per_period": 2}, "samples_per_period"),
        (Transient, {"gap": 1.0, "step": -1.5}, "step"),
        (Approach, {"gap_end": -0.1}, "gap_end"),
        (Sweep, {"omega_start": 1.2, "omega_stop": 1.0}, "omega_stop"),
        (Sweep, {"direction": "sideways"}, "direction"),
        (Sweep, {"n_points": 1}, "n_points"),
    ],
)
def test_bad_settings_raise(cls, kwargs, name):
    with pytest.raises(ValueError, match=name):
        cls(**kwargs)


def test_integrator_strategy_is_used(cl1):
    """Finer RK4 steps converge at 4th order: the integrator object is really used."""
    runs = {k: SteadyState(omega=1.0, n_periods=5, settle_periods=0, samples_per_period=50,
                           integrator=RK4(substeps=k)).run(tapping(cl1)).deflection
            for k in (4, 8, 64)}
    e4 = np.max(np.abs(runs[4] - runs[64]))
    e8 = np.max(np.abs(runs[8] - runs[64]))
    assert e4 / e8 > 10  # ~16 for 4th order


def test_transient_labels_see_the_step(cl1):
    """Labels of a multi-segment record use each segment's own gap (regression)."""
    r = Transient(omega=1.0, gap=1.0, step=-0.3, periods_before=5, periods_after=100).run(
        tapping(cl1))
    assert r.labels["min_gap"] == pytest.approx(np.min(r.gap))
    k = r.meta["step_index"]
    assert np.min(r.gap[k:]) < np.min(r.gap[:k])  # closer surface: deeper taps after the step


def test_electrostatic_is_held_at_contact():
    """Long-range terms saturate at a0 in contact, so deep indentation stays finite."""
    from simulator.forces import Electrostatic

    f = DMT(a0=0.2, vdw=0.002, stiffness=20.0) + Electrostatic(strength=0.05, radius=1.0)
    z = np.array([0.2, 0.1, 0.01, 1e-6])
    contact = np.ones(4, dtype=bool)
    es_part = f(z, 0.0, contact) - DMT(a0=0.2, vdw=0.002, stiffness=20.0)(z, 0.0, contact)
    np.testing.assert_allclose(es_part, -0.05 / (0.2 * 1.2))


def test_no_drift_with_large_absolute_time(cl1):
    """The kernel keeps time relative to the segment start: a run starting at tau = 1e6 gives
    the same samples as one starting at 0 (regression: accumulated absolute time drifted the
    drive phase on long sweeps)."""
    from simulator import State

    s = tapping(cl1)
    runs = []
    for tau0 in (0.0, 1e6):
        st = State.free_orbit(s, omega=1.0, tau=tau0)
        seg = RK4(substeps=4).run(s, st, omega=1.0, n_samples=20000, dt=2 * np.pi / 200)
        runs.append(seg)
    np.testing.assert_array_equal(runs[0].q, runs[1].q)
    assert runs[1].end.tau[0] == 1e6 + 20000 * (2 * np.pi / 200)
