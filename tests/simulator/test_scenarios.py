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
from simulator.labels import lock_in, recorded_drive_phase
from simulator.scenarios import Spectroscopy


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
        (Spectroscopy, {"gaps": [1.0, -0.5]}, "gaps"),
        (Spectroscopy, {"gap_ratios": []}, "gap_ratios"),
        (Spectroscopy, {"gaps": [1.0, 0.8], "drive_phases": [0.0]}, "drive_phases"),
        (Spectroscopy, {"n_periods": -1}, "n_periods"),
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


# ---------------------------------------------------------------------------- spectroscopy
SPECTRO = {"n_periods": 10, "settle_periods": 400, "samples_per_period": 200}


def first_harmonic(x, phase0, omega, dt):
    """Complex amplitude of ``x`` against ``cos(omega tau + phase0)`` over whole periods."""
    spp = int(round(2 * np.pi / (omega * dt)))
    n = (x.size // spp) * spp
    return lock_in(x[:n], phase0 + omega * dt * np.arange(n))


def test_spectroscopy_rows_are_steady_records_up_to_the_phase(cl1):
    """Row i = SteadyState at gap g_i (same settling from the free orbit), shifted by the
    drive phase: with a phase offset of k samples, row[j] = steady[j + k]."""
    system = tapping(cl1)
    gaps = [1.3, 0.9, 0.6]
    shifts = [0, 7, 31]
    steady = [SteadyState(gap=g, **SPECTRO).run(system) for g in gaps]
    theta_s = float(steady[0].phase[0])
    spp = SPECTRO["samples_per_period"]
    phases = [theta_s + 2 * np.pi * k / spp for k in shifts]
    r = Spectroscopy(gaps=gaps, drive_phases=phases, **SPECTRO).run(system)
    assert r.q.shape == (3, 1, 10 * spp) and r.has_rows and not r.is_sweep
    np.testing.assert_allclose(r.phase[:, 0], phases, atol=1e-9)
    np.testing.assert_allclose(r.rest_gap[:, 0], gaps)
    for i, (k, s) in enumerate(zip(shifts, steady, strict=True)):
        row, ref = r.deflection[i], s.deflection
        scale = np.ptp(ref)
        diff = np.abs(row[: row.size - k] - ref[k:])
        # what remains is the transient not yet settled after 400 periods; it still decays
        # along the record
        assert np.max(diff) < 5e-5 * scale
        assert np.max(diff[-spp:]) < 1e-5 * scale
        assert r.labels["amplitude"][i] == pytest.approx(s.labels["amplitude"], rel=1e-5)
        assert r.labels["regime"][i] == s.labels["regime"] == "repulsive"
    # without drive phases the rows are the steady runs exactly
    plain = Spectroscopy(gaps=gaps[:1], **SPECTRO).run(system)
    np.testing.assert_allclose(plain.deflection[0], steady[0].deflection, rtol=0, atol=1e-12)


def test_spectroscopy_gap_ratios_scale_the_free_amplitude(cl1):
    system = tapping(cl1, ratio=1.5)
    sc = Spectroscopy(gap_ratios=[0.9, 0.5])
    np.testing.assert_allclose(sc.rest_gaps(1.5), [1.35, 0.75])
    assert sc.n_rows == 2
    assert Spectroscopy(gaps=[1.0], gap_ratios=[0.9, 0.5]).n_rows == 1  # gaps win
    r = Spectroscopy(gap_ratios=[0.9, 0.5], n_periods=2, settle_periods=5).run(system)
    np.testing.assert_allclose(r.rest_gap[:, 0], [1.35, 0.75], rtol=1e-12)


@pytest.mark.parametrize("omega", [0.99, 1.01])
def test_spectroscopy_drive_phase_is_the_drives_phase(cl1, omega):
    """Off resonance (lag far from pi/2): the lag of the deflection behind
    cos(Omega tau + drive_phase) is the simulator's lock-in phase, and the drive's work per
    cycle pi B A sin(lag) equals the drive-energy label."""
    system = tapping(cl1)
    rng = np.random.default_rng(3)
    phases = rng.uniform(-np.pi, np.pi, 3)
    r = Spectroscopy(omega=omega, gaps=[1.2, 0.9, 0.6], drive_phases=phases, **SPECTRO).run(
        system)
    recorded = r.drive_phase
    np.testing.assert_allclose(np.exp(1j * recorded), np.exp(1j * phases), atol=1e-9)
    b = system.excitation.amplitude
    for i in range(3):
        a1 = first_harmonic(r.deflection[i], recorded[i], omega, r.dt)
        lag = -np.angle(a1)
        assert np.exp(1j * lag) == pytest.approx(np.exp(1j * r.labels["phase"][i]), abs=1e-6)
        work = np.pi * b * abs(a1) * np.sin(lag)
        assert work == pytest.approx(r.labels["drive_energy"][i], rel=2e-3)


def test_base_excitation_drive_phase_is_the_base_motion():
    """Free base-driven oscillator: the deflection lags the base motion y cos(Omega tau +
    drive_phase) by the linear oscillator's atan2(Omega/Q, 1 - Omega^2)."""
    q_factor, omega = 50.0, 0.98
    cl = Cantilever.rectangular(n_modes=1, quality_factor=q_factor)
    system = System(cl, NoInteraction(), BaseExcitation(amplitude=0.01))
    r = Spectroscopy(omega=omega, gaps=[1.0], drive_phases=[0.4], n_periods=10,
                     settle_periods=0).run(system)
    phase = r.drive_phase
    assert phase[0] == pytest.approx(0.4 - np.pi / 2)
    assert recorded_drive_phase(0.4, system, omega) == pytest.approx(0.4 - np.pi / 2)
    lag = -np.angle(first_harmonic(r.deflection[0], phase[0], omega, r.dt))
    assert lag == pytest.approx(np.arctan2(omega / q_factor, 1 - omega**2), abs=1e-6)


@pytest.mark.parametrize("viscous", [False, True])
def test_spectroscopy_physics_per_row(cl1, viscous):
    """Repulsive branch: the amplitude shrinks with the gap; per row, the drive's energy
    equals the cantilever's damping plus the energy into the sample (labels)."""
    force = (ViscoelasticDMT(a0=0.2, vdw=0.002, stiffness=20.0, viscosity=2.0) if viscous
             else DMT(a0=0.2, vdw=0.002, stiffness=20.0))
    gaps = np.array([1.4, 1.2, 1.0, 0.8, 0.6])
    r = Spectroscopy(gaps=gaps, **SPECTRO).run(tapping(cl1, force))
    lab = r.labels
    assert lab["regime"] == ["repulsive"] * 5
    amp = np.asarray(lab["amplitude"])
    assert np.all(np.diff(amp) < 0)
    assert np.all(amp < gaps + 0.2)  # the surface (plus at most a0 of indentation) limits it
    drive = np.asarray(lab["drive_energy"])
    balance = drive - np.asarray(lab["damping_energy"]) - np.asarray(lab["dissipated_energy"])
    assert np.all(np.abs(balance) < 2e-3 * drive)
    loss = np.asarray(lab["dissipated_energy"])
    if viscous:
        assert np.all(loss > 1e-2 * drive)
    else:
        assert np.all(np.abs(loss) < 1e-4 * drive)
