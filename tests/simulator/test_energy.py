"""Energy balance of the integrated work integrals (``State.work``), model by model.

Work columns: 0 drive input ``int sum_i f_i v_i``, 1 cantilever damping ``int sum_i D_i v_i^2``,
2 work on the tip--sample force ``int F sum_i s_i v_i``, 3 energy into the sample
``-int F z'``, 4 time in contact. The modal equations give, over any interval,

    W0 = W1 + W2 + Delta(T + V),  T + V = sum_i (v_i^2 + K_i q_i^2) / 2,

and, with a fixed rest gap and tip drive (``z' = -sum v``), W2 = W3. Splitting the tip--sample
force into a conservative part ``-dU/dz`` and the rest, ``W3 = Delta U + W_diss``: a conservative
model delivers no net energy to the sample (``W_diss = 0``), a dissipative one ``W_diss > 0``.
(Adding ``Delta U`` to the mechanical energy *and* counting W2 would count the conservative
work twice.) Run with ``-s`` for the table of measured residuals.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, trapezoid
from simcases import CONSERVATIVE, DISSIPATIVE, FORCE_MODELS, mechanical_energy, tapping

from simulator import RK4, BaseExcitation, Cantilever, Segment, State, System
from simulator.forces import AbstractForceModel
from simulator.integrate import SolveIVP

SETTLE_PERIODS = 600  # >> 2Q / (2 pi) = 32 periods (Q = 100)
PERIODS, PER = 5, 1000  # measured window: whole periods, fine samples for the quadratures


def potential_change(model: AbstractForceModel, z0: float, z1: float, c0: int, c1: int) -> float:
    """``U(z1) - U(z0) = -int_{z0}^{z1} F(z, zdot=0) dz`` along the branch the tip is on."""
    if model.break_indentation != 0.0:  # hysteretic: U is defined per branch
        assert c0 == c1, "window must start and end on the same branch"

        def f(z: float) -> float:
            return float(model(z, 0.0, bool(c0)))
    else:
        def f(z: float) -> float:
            return float(model(z, 0.0))  # approach branch = the regime at z
    lo, hi = sorted((z0, z1))
    pts = [model.a0] if model.has_contact and lo < model.a0 < hi else None
    val = quad(f, lo, hi, points=pts, epsabs=1e-15, epsrel=1e-13, limit=200)[0]
    return -val if z1 >= z0 else val


def end_values(system: System, seg: Segment):
    """Gap, gap rate and force at the end state (to close the sample quadratures)."""
    e = seg.end
    th = float(e.theta[0])
    y = system.excitation.gap_modulation
    z = float(e.gap[0] - e.q[0].sum() - y * math.sin(th))
    zd = float(seg.gap_rate[0] - e.v[0].sum() - y * seg.omega[0] * math.cos(th))
    return z, zd, float(system.force(z, zd, bool(e.contact[0])))


def sample_quadratures(system: System, seg: Segment) -> dict[str, float]:
    """Work integrals recomputed from the recorded samples (trapezoid), closed at the end."""
    z_end, zd_end, f_end = end_values(system, seg)
    cl = system.cantilever
    v = np.concatenate([seg.v[0], seg.end.v[0][:, None]], axis=1)
    force = np.r_[seg.force[0], f_end]
    contact = np.r_[seg.contact[0], seg.end.contact[0]].astype(bool)
    tau = seg.tau_start[0] + seg.dt * np.arange(seg.n_samples + 1)
    theta = seg.theta_start[0] + seg.omega[0] * (tau - tau[0])
    y = system.excitation.gap_modulation
    zdot = seg.gap_rate[0] - v.sum(axis=0) - y * seg.omega[0] * np.cos(theta)
    dc, ds = system.excitation.modal_drive(cl, float(seg.omega[0]))
    drive = dc[:, None] * np.cos(theta) + ds[:, None] * np.sin(theta)
    damp = np.where(contact, np.asarray(cl.contact_damping)[:, None],
                    np.asarray(cl.damping)[:, None])
    gains = np.asarray(cl.force_gain)[:, None]
    return {
        "W0": trapezoid(np.sum(drive * v, axis=0), tau),
        "W1": trapezoid(np.sum(damp * v**2, axis=0), tau),
        "W2": trapezoid(force * np.sum(gains * v, axis=0), tau),
        "W3": trapezoid(-force * zdot, tau),
        "F": trapezoid(force, tau),
    }


def balance(system: System, seg: Segment) -> dict[str, float]:
    w = seg.work[0]
    d_mech = float(mechanical_energy(system, seg.end.q, seg.end.v)[0]
                   - mechanical_energy(system, seg.start.q, seg.start.v)[0])
    z0 = seg.gap[0, 0]
    z1, _, _ = end_values(system, seg)
    d_u = potential_change(system.force, float(z0), z1, int(seg.start.contact[0]),
                           int(seg.end.contact[0]))
    return {"W": w, "dE": d_mech, "dU": d_u, "residual": w[0] - w[1] - w[2] - d_mech,
            "diss": w[3] - d_u}


def settled_window(name: str) -> tuple[System, Segment]:
    """Settle on the tapping orbit, then record ``PERIODS`` whole periods (same step: a change
    of step would restart a small numerical transient)."""
    t = tapping(name)
    rk4 = RK4(substeps=None if t.substeps is None else math.ceil(t.substeps * 200 / PER))
    kw = {"omega": t.omega, "dt": 2 * math.pi / (t.omega * PER)}
    settle = rk4.run(t.system, State.free_orbit(t.system, omega=t.omega),
                     n_samples=SETTLE_PERIODS * PER, **kw)
    return t.system, rk4.run(t.system, settle.end, n_samples=PERIODS * PER,
                             record_velocity=True, **kw)


# ------------------------------------------------------------------ (b) every model, tapping
@pytest.mark.parametrize("name", list(FORCE_MODELS))
def test_energy_balance_per_cycle(name: str) -> None:
    system, seg = settled_window(name)
    b = balance(system, seg)
    w, w0 = b["W"], b["W"][0]
    quad_w = sample_quadratures(system, seg)
    n_switch = int(np.count_nonzero(np.diff(np.r_[seg.contact[0], seg.end.contact[0]])))
    print(f"\n  {name:24s} per cycle: drive {w0 / PERIODS:.4e}  damping {w[1] / PERIODS:.4e}  "
          f"W2 {w[2] / PERIODS:+.3e}  sample {w[3] / PERIODS:+.3e}  dE {b['dE']:+.1e}  "
          f"dU {b['dU']:+.1e} | residual/W0 {b['residual'] / w0:+.1e}  "
          f"W_diss/W0 {b['diss'] / w0:+.2e}  |W3 - trapz|/W0 {abs(w[3] - quad_w['W3']) / w0:.1e}"
          f"  contact {w[4] / (2 * math.pi * PERIODS):.3f}")
    assert w0 > 0.0
    # (i) the drive input goes into damping, the tip--sample force and stored energy
    assert abs(b["residual"]) < 1e-6 * w0  # brief: 1 %; measured <= 1e-8
    assert w[2] == pytest.approx(w[3], rel=1e-12, abs=1e-15 * w0)  # tip drive, fixed gap
    # (ii) energy delivered to the sample
    if name in CONSERVATIVE:
        assert abs(b["diss"]) < 1e-5 * w0
        assert abs(w[3]) < 1e-3 * w0  # steady state: ~nothing per cycle
    else:
        assert name in DISSIPATIVE
        assert b["diss"] > 1e-4 * w0
    # (iii) independent trapezoid quadratures of the recorded samples
    assert abs(quad_w["W3"] - w[3]) < 1e-4 * w0
    assert quad_w["W0"] == pytest.approx(w0, rel=1e-4)
    assert quad_w["W1"] == pytest.approx(w[1], rel=1e-4)
    # (iv) time in contact == sampled contact fraction, up to one sample per switch
    assert abs(w[4] - seg.dt * np.sum(seg.contact)) <= seg.dt * (n_switch + 1)
    if FORCE_MODELS[name].has_contact and name not in ("vdw_sphere", "electrostatic"):
        assert n_switch >= 2 * PERIODS - 1  # really tapping: contact formed and broken


@pytest.mark.parametrize("name", ["dmt", "visco", "jkr_hysteretic"])
def test_dissipation_per_cycle_is_steady(name: str) -> None:
    """In a period-1 steady state every cycle dissipates the same energy into the sample."""
    system, seg = settled_window(name)
    f, zd = seg.force[0], -seg.v[0].sum(axis=0)
    per_cycle = np.array([trapezoid(-(f * zd)[k * PER:(k + 1) * PER + 1], dx=seg.dt)
                          for k in range(PERIODS - 1)])
    x = seg.deflection[0]
    assert np.max(np.abs(x[PER:] - x[:-PER])) < 1e-6 * np.ptp(x)  # period-1
    assert np.ptp(per_cycle) < 1e-3 * seg.work[0, 0] / PERIODS


# ------------------------------------------------------------------ base drive, 2 modes, ramp
@pytest.mark.parametrize("name", ["dmt", "visco", "jkr_hysteretic", "electrostatic+dmt"])
def test_energy_balance_base_drive_two_modes_with_contact_damping(name: str) -> None:
    """Dither drive, two modes, piecewise modal damping (lower Q in contact)."""
    cl = Cantilever.rectangular(n_modes=2, quality_factor=100, contact_quality_factors=[40, 60])
    system = System(cl, FORCE_MODELS[name], BaseExcitation.for_free_amplitude(cl, 1.0, 1.5))
    start = State.free_orbit(system, omega=1.0)
    settle = RK4().run(system, start, omega=1.0, n_samples=300 * 200, dt=2 * math.pi / 200)
    seg = RK4().run(system, settle.end, omega=1.0, n_samples=PERIODS * PER,
                    dt=2 * math.pi / PER, record_velocity=True)
    b = balance(system, seg)
    w, w0 = b["W"], b["W"][0]
    quad_w = sample_quadratures(system, seg)
    print(f"\n  base, 2 modes, {name}: residual/W0 {b['residual'] / w0:+.1e}  "
          f"W_diss/W0 {b['diss'] / w0:+.2e}  |W2 - trapz|/W0 {abs(w[2] - quad_w['W2']) / w0:.1e}"
          f"  |W1 - trapz|/W0 {abs(w[1] - quad_w['W1']) / w0:.1e}")
    assert seg.contact.any()
    assert abs(b["residual"]) < 1e-6 * w0
    assert abs(quad_w["W1"] - w[1]) < 1e-3 * w0  # D jumps at the events: O(dt) quadrature
    assert abs(quad_w["W2"] - w[2]) < 1e-4 * w0
    assert abs(quad_w["W3"] - w[3]) < 1e-4 * w0
    if FORCE_MODELS[name].dissipative:
        assert b["diss"] > 1e-4 * w0
    else:
        assert abs(b["diss"]) < 1e-5 * w0


def test_energy_on_an_approach_ramp() -> None:
    """Rest gap ramped 1.8 -> 1.0 (from free oscillation into tapping): W3 = Delta U
    (conservative) and W2 = W3 + g' int F."""
    t = tapping("dmt")
    periods, per = 40, 400
    dt = 2 * math.pi / per
    rate = -0.8 / (periods * 2 * math.pi)
    start = State.free_orbit(t.system, omega=1.0, gap=1.8)
    seg = RK4().run(t.system, start, omega=1.0, n_samples=periods * per, dt=dt, gap_rate=rate,
                    record_velocity=True)
    b = balance(t.system, seg)
    w, w0 = b["W"], b["W"][0]
    quad_w = sample_quadratures(t.system, seg)
    print(f"\n  ramp, dmt: residual/W0 {b['residual'] / w0:+.1e}  W3 {w[3]:+.4e}  "
          f"dU {b['dU']:+.4e}  W2 - W3 {w[2] - w[3]:+.4e} vs g' int F {rate * quad_w['F']:+.4e}")
    assert seg.end.gap[0] == pytest.approx(1.0, rel=1e-12)
    assert seg.contact[0, :per].sum() == 0 and seg.contact[0, -per:].any()
    assert abs(b["residual"]) < 1e-6 * w0
    assert abs(b["diss"]) < 1e-5 * w0
    assert abs(w[2] - w[3] - rate * quad_w["F"]) < 1e-4 * abs(w[2] - w[3])


@pytest.mark.parametrize("name", ["visco", "jkr_hysteretic"])
def test_solve_ivp_energy_balance(name: str) -> None:
    """The reference integrator accumulates the same work integrals (2 settled periods)."""
    system, rk = settled_window(name)
    kw = {"omega": 1.0, "n_samples": 2 * 100, "dt": 2 * math.pi / 100, "record_velocity": True}
    seg = SolveIVP(rtol=1e-10, atol=1e-12).run(system, rk.start, **kw)
    b = balance(system, seg)
    w0 = b["W"][0]
    fast = RK4(substeps=10).run(system, rk.start, **kw).work[0]
    dw = np.max(np.abs(fast[:4] - b["W"][:4]))
    print(f"\n  SolveIVP {name}: residual/W0 {b['residual'] / w0:+.1e}, W_diss/W0 "
          f"{b['diss'] / w0:.3e}; max|W_RK4 - W_ivp|/W0 {dw / w0:.1e}; contact time "
          f"{b['W'][4]:.6f} vs RK4 {fast[4]:.6f}")
    assert abs(b["residual"]) < 1e-8 * w0
    assert b["diss"] > 1e-4 * w0
    assert dw < 1e-5 * w0  # RK4 at 1000 steps/period
    assert fast[4] == pytest.approx(b["W"][4], abs=1e-5)
