"""Slow-flow curve model: cycle averages against brute force, the lever's own transient,
the energy balance behind the dissipation formula, and agreement with the time-domain
simulator plus lock-in."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.curves import CurveLaw, SlowFlowModel, dissipated_energy, drive_from_free
from afmlearn.curves import _kernel as K
from simulator import RK4, Cantilever, System, TipExcitation
from simulator.forces import DMT
from simulator.lockin import LockIn
from simulator.scenarios.lockin import LockInCurve

LAW = CurveLaw(a0=0.03, vdw=2e-5, stiffness=20.0, exponent=1.7, visco=0.3, damping=1e-3,
               decay_length=0.1, electrostatic=1e-4, radius=0.5, neck=0.02, far_damping=3e-4,
               far_decay_length=15.0)


def brute_averages(law, d, a, omega, n=400_000):
    th = 2 * np.pi * (np.arange(n) + 0.5) / n
    z = d - a * np.cos(th)
    zd = a * omega * np.sin(th)
    touched = d - a <= law.a0
    retract = np.sin(th) > 0
    mode = np.where(z <= law.a0, 1, 0)
    mode = np.where(retract & touched & (z > law.a0) & (z <= law.a0 + law.neck), 2, mode)
    f = law.force(z, zd, mode)
    return np.mean(f * np.sin(th)), np.mean(f * np.cos(th))


@pytest.mark.parametrize("d,a", [(1.2, 1.0), (1.02, 1.0), (0.99, 1.0), (0.5, 0.3)])
def test_cycle_averages_against_brute_force(d, a):
    got = K.averages(LAW.vector(), d, a, 1.0, K._GL_X, K._GL_W)
    ref = brute_averages(LAW, d, a, 1.0)
    scale = max(abs(ref[0]), abs(ref[1]))
    # 8 Gauss nodes per smooth piece: sqrt(delta) edges of the contact terms limit it to ~1e-3
    np.testing.assert_allclose(got, ref, atol=1e-3 * scale)


def test_free_transient_has_the_time_constant_2q():
    q, b = 80.0, 1.0 / 80.0
    h = 2 * np.pi
    gap = np.full(400, 5.0)
    amp, phi = K.integrate(CurveLaw(a0=0.03).vector(), gap, h, 1e-3, math.pi / 2, q, 1.0, b,
                           K._GL_X, K._GL_W, 0.25)
    tau = h * np.arange(gap.size)
    exact = q * b - (q * b - 1e-3) * np.exp(-tau / (2 * q))
    np.testing.assert_allclose(amp, exact, atol=1e-6)
    np.testing.assert_allclose(phi, math.pi / 2, atol=1e-9)


def test_far_damping_lowers_q_as_an_extra_lever_damping():
    """A far-field damping of decay much longer than the gap is a constant extra damping c:
    the averaged flow is then the free lever with 1/Q -> 1/Q + c, amplitude B / (1/Q + c)
    at resonance, reached with the time constant 2 / (1/Q + c)."""
    q, b, c, h = 80.0, 1.0 / 80.0, 4e-3, 2 * np.pi
    gap = np.full(600, 5.0)
    law = CurveLaw(a0=0.03, far_damping=c, far_decay_length=1e9)
    amp, phi, _ = K.integrate_adaptive(law.vector(), gap, h, 1e-3, math.pi / 2, q, 1.0, b,
                                       K._GL_X, K._GL_W, 1e-9, 4 * q, h / 16)
    tau = h * np.arange(gap.size)
    d = 1.0 / q + c
    exact = b / d - (b / d - 1e-3) * np.exp(-tau * d / 2)
    np.testing.assert_allclose(amp, exact, atol=1e-6)
    np.testing.assert_allclose(phi, math.pi / 2, atol=1e-9)
    # the RK4 reference gives the same
    amp4, _ = K.integrate(law.vector(), gap, h, 1e-3, math.pi / 2, q, 1.0, b, K._GL_X,
                          K._GL_W, 0.05)
    np.testing.assert_allclose(amp4, exact, atol=1e-6)


def test_drive_from_free_phase_inverts_the_free_response():
    for w in (0.995, 1.0, 1.004):
        q = 187.0
        phase = math.atan2(w / q, 1 - w * w)
        w2, b = drive_from_free(phase, q)
        assert w2 == pytest.approx(w, abs=1e-9)
        assert b / math.hypot(1 - w * w, w / q) == pytest.approx(1.0, rel=1e-9)


def test_dissipation_formula_is_the_energy_balance():
    """Steady state with damping: the formula equals -2 pi A <F sin theta> per cycle."""
    law = CurveLaw(a0=0.03, vdw=1e-5, stiffness=20.0, damping=5e-3, decay_length=0.2,
                   visco=0.5)
    q = 100.0
    model = SlowFlowModel(quality_factor=q, omega=1.0, drive=1.0 / q, step=2 * np.pi,
                          settle=20.0)
    tau = np.array([0.0, 1.0])
    amp, phi = model.predict(law, tau, np.array([0.98, 0.98]))
    fs, _ = K.averages(law.vector(), 0.98, amp[0], 1.0, K._GL_X, K._GL_W)
    direct = -2 * np.pi * amp[0] * fs
    formula = dissipated_energy(amp[:1], phi[:1], free_amplitude=1.0, free_phase=math.pi / 2,
                                quality_factor=q)[0]
    assert direct > 0
    assert formula == pytest.approx(direct, rel=1e-3)


def test_slow_flow_follows_the_time_domain_curve():
    q = 60.0
    cl = Cantilever.rectangular(n_modes=1, quality_factor=q)
    force = DMT(a0=0.03, vdw=3e-5, stiffness=30.0)
    system = System(cl, force, TipExcitation.for_free_amplitude(cl, 1.0, 1.0))
    li = LockIn(bandwidth=0.01, order=4, output_interval=8 * 2 * np.pi)
    scen = LockInCurve(gap_start=1.6, gap_end=0.4, n_periods=800, lockin=li,
                       samples_per_period=40, integrator=RK4(steps_per_period=120))
    rec = scen.run(system).meta["curve"]
    model = SlowFlowModel(quality_factor=q, omega=1.0, drive=1.0 / q, lockin=li,
                          step=2 * np.pi)
    law = CurveLaw(a0=0.03, vdw=3e-5, stiffness=30.0)
    amp, phi = model.predict(law, rec.tau, rec.rest_gap)
    # the ramp is fast (13 lever time constants per ramp): the transient lag is in both
    assert np.max(np.abs(amp - rec.amplitude)) < 0.01
    err = np.degrees(np.abs(phi - rec.phase))
    # (the averaged model drops the static deflection and the higher harmonics: <= ~1 deg)
    assert np.median(err) < 0.3 and np.percentile(err, 95) < 1.5
    # both jump from the attractive to the repulsive branch (phase below 85 deg) at the
    # same rest gap on the approach
    app = rec.segment == 0
    first = [np.argmax((p < np.radians(85.0)) & app) for p in (rec.phase, phi)]
    assert abs(rec.rest_gap[first[0]] - rec.rest_gap[first[1]]) <= 0.02
    # and a quasi-static model (no lever transient, no filter) is measurably worse
    slow = SlowFlowModel(quality_factor=q, omega=1.0, drive=1.0 / q, step=2 * np.pi)
    amp_qs, _ = slow.predict(law, rec.tau * 50, rec.rest_gap)
    assert np.max(np.abs(amp_qs - rec.amplitude)) > 2 * np.max(np.abs(amp - rec.amplitude))


def _ramp_case():
    """A ramp through the attractive-to-repulsive jump and back with every force term."""
    q, h = 60.0, 2 * np.pi
    gap = np.concatenate([np.full(100, 1.6), np.linspace(1.6, 0.4, 900),
                          np.linspace(0.4, 1.6, 900)])
    return LAW, gap, h, q


def test_adaptive_kernel_matches_an_independent_ode_solver():
    """Dormand--Prince with step control against scipy's DOP853 at tight tolerances (a plain
    reference: the same averaged rates, the gap linear between grid points)."""
    from scipy.integrate import solve_ivp

    law, gap, h, q = _ramp_case()
    v = law.vector()
    t_grid = h * np.arange(gap.size)

    def rhs(t, y):
        d = np.interp(t, t_grid, gap)
        return K.rates(v, d, max(y[0], 1e-9), y[1], q, 1.0, 1.0 / q, K._GL_X, K._GL_W)

    ref = solve_ivp(rhs, (0.0, t_grid[-1]), [1.0, math.pi / 2], method="DOP853",
                    t_eval=t_grid, rtol=1e-10, atol=1e-11, max_step=h)
    amp, phi, nsteps = K.integrate_adaptive(v, gap, h, 1.0, math.pi / 2, q, 1.0, 1.0 / q,
                                            K._GL_X, K._GL_W, 1e-7, 4 * q, h / 16)
    # the jump between the branches is in the ramp: the phase moves by > 20 deg
    assert np.ptp(ref.y[1]) > math.radians(20.0)
    np.testing.assert_allclose(amp, ref.y[0], atol=5e-6)
    np.testing.assert_allclose(phi, ref.y[1], atol=5e-5)
    # and the fixed-grid RK4 of the first version agrees as well (to 2e-5: its order drops
    # at the contact onset, where the averages have a square-root edge in the gap)
    amp4, phi4 = K.integrate(v, gap, h, 1.0, math.pi / 2, q, 1.0, 1.0 / q, K._GL_X, K._GL_W,
                             0.05)
    np.testing.assert_allclose(amp4, ref.y[0], atol=5e-5)
    assert 0 < nsteps < gap.size


def test_adaptive_steps_are_long_in_the_far_field():
    """Far from the surface the flow is smooth: far fewer steps than grid points, and the
    free transient is still the exact exponential of time constant 2Q."""
    q, b, h = 80.0, 1.0 / 80.0, 2 * np.pi
    gap = np.full(4000, 5.0)
    amp, phi, nsteps = K.integrate_adaptive(CurveLaw(a0=0.03).vector(), gap, h, 1e-3,
                                            math.pi / 2, q, 1.0, b, K._GL_X, K._GL_W, 1e-7,
                                            4 * q, h / 16)
    tau = h * np.arange(gap.size)
    exact = q * b - (q * b - 1e-3) * np.exp(-tau / (2 * q))
    np.testing.assert_allclose(amp, exact, atol=1e-6)
    assert nsteps < gap.size / 10


def test_model_default_and_reference_integrations_agree():
    """SlowFlowModel: the adaptive default and the RK4 reference (tolerance=None) give the
    same lock-in curve (the far-field term off: both stay as measured before it; the term is
    checked against DOP853 above)."""
    law, gap, h, q = _ramp_case()
    law = law.replace(far_damping=0.0)
    tau = h * np.arange(gap.size)
    li = LockIn(bandwidth=0.01, order=4, output_interval=8 * h)
    kw = {"quality_factor": q, "omega": 1.0, "drive": 1.0 / q, "lockin": li, "step": h}
    a1, p1 = SlowFlowModel(**kw).predict(law, tau, gap)
    a2, p2 = SlowFlowModel(tolerance=None, max_turn=0.05, **kw).predict(law, tau, gap)
    # (both are approximations where the neck's switch makes the rates jump: 0.03 deg)
    np.testing.assert_allclose(a1, a2, atol=5e-5)
    np.testing.assert_allclose(p1, p2, atol=5e-4)
    with pytest.raises(ValueError, match="tolerance"):
        SlowFlowModel(tolerance=-1.0, **kw)
