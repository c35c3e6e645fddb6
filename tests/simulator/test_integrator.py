"""Integrators: linear response, batching, input validation, convergence order, RK4 vs SolveIVP.

Run with ``-s`` to see the measured tables (errors, orders, timings).
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np
import pytest
from simcases import FORCE_MODELS, lockin, tapping, two_pi_over

from simulator import (
    RK4,
    BaseExcitation,
    Cantilever,
    State,
    System,
    TipExcitation,
)
from simulator.forces import NoInteraction
from simulator.integrate import SolveIVP

# explicit modal parameters (independent of Cantilever.rectangular's defaults)
K3 = (1.0, 6.267**2, 17.55**2)
D3 = (0.01, 6.267 / 250.0, 17.55 / 400.0)  # Q = 100, 250, 400
B3 = (1.566, -0.868, 0.509)


def cantilever(n: int, damping=D3) -> Cantilever:
    return Cantilever(stiffness=K3[:n], damping=damping[:n], base_participation=B3[:n])


def analytic_modes(n: int, kind: str, omega: float, amplitude: float, damping=D3) -> np.ndarray:
    """Complex modal amplitudes ``Z_i``, ``q_i = Re(Z_i exp(i Omega tau))``, of the linear
    oscillators ``q'' + D q' + K q = f_i``: tip drive ``f_i = A cos``, base drive
    ``f_i = B_i Omega^2 y sin = Re(-i B_i Omega^2 y exp(i Omega tau))``."""
    k, d, b = (np.asarray(a[:n]) for a in (K3, damping, B3))
    f = np.full(n, amplitude, complex) if kind == "tip" else -1j * b * omega**2 * amplitude
    return f / (k - omega**2 + 1j * d * omega)


def excitation(kind: str, amplitude: float):
    return TipExcitation(amplitude=amplitude) if kind == "tip" else BaseExcitation(
        amplitude=amplitude)


# ------------------------------------------------------------------ (a) linear response
FREE_CASES = [(1, "tip", 1.0), (1, "tip", 0.97), (1, "base", 1.02), (2, "tip", 1.0),
              (2, "base", 6.2), (3, "tip", 0.95), (3, "base", 1.0), (3, "base", 17.3)]


@pytest.mark.parametrize(("n", "kind", "omega"), FREE_CASES)
def test_free_steady_state_matches_linear_response(n: int, kind: str, omega: float) -> None:
    """Start on the analytic orbit; after 20 periods the lock-in amplitude and phase of every
    mode and of the tip are those of the linear receptance (relative error <= 1e-4)."""
    amp = 0.5 if kind == "tip" else 0.01
    system = System(cantilever(n), NoInteraction(), excitation(kind, amp))
    z = analytic_modes(n, kind, omega, amp)
    np.testing.assert_allclose(State.free_orbit(system, omega=omega).q[0], z.real, rtol=1e-12)
    state = State(z.real[None], (1j * omega * z).real[None], 0, 0.0, 0.0, 1.0)
    per = 64
    seg = RK4().run(system, state, omega=omega, n_samples=30 * per, dt=two_pi_over(per, omega))
    window = slice(20 * per, 30 * per)
    phase = seg.phase[0, window]
    modes = lockin(seg.q[0, :, window], phase)
    tip = lockin(seg.deflection[0, window], phase)
    err_modes = np.abs(modes - z) / np.abs(z)
    err_tip = abs(tip - z.sum()) / abs(z.sum())
    print(f"\n  n={n} {kind} Omega={omega}: |X|={abs(tip):.6g} phase={np.angle(tip):+.6f} "
          f"rel.err tip {err_tip:.2e}, modes {np.array2string(err_modes, precision=2)}")
    assert err_tip <= 1e-4
    assert np.all(err_modes <= 1e-4)


def test_transient_decays_to_linear_response() -> None:
    """From rest, two strongly damped modes under base drive settle on the receptance."""
    damping = (0.1, 0.5, 1.0)
    system = System(cantilever(2, damping), NoInteraction(), BaseExcitation(amplitude=0.02))
    omega, per = 0.9, 64
    rest = State(np.zeros((1, 2)), np.zeros((1, 2)), 0, 0.0, 0.0, 1.0)
    seg = RK4().run(system, rest, omega=omega, n_samples=130 * per, dt=two_pi_over(per, omega))
    window = slice(120 * per, 130 * per)
    modes = lockin(seg.q[0, :, window], seg.phase[0, window])
    z = analytic_modes(2, "base", omega, 0.02, damping)
    assert np.all(np.abs(modes - z) / np.abs(z) <= 1e-4)
    assert abs(seg.q[0, 0, 0]) == 0.0 and abs(seg.q[0, 0, 5 * per]) > 0.1 * abs(z[0])


@pytest.mark.parametrize(("n", "kind", "omega"), [(1, "tip", 1.0), (2, "base", 1.05)])
def test_solve_ivp_free_response(n: int, kind: str, omega: float) -> None:
    amp = 0.5 if kind == "tip" else 0.01
    system = System(cantilever(n), NoInteraction(), excitation(kind, amp))
    z = analytic_modes(n, kind, omega, amp)
    state = State(z.real[None], (1j * omega * z).real[None], 0, 0.0, 0.0, 1.0)
    per = 32
    seg = SolveIVP().run(system, state, omega=omega, n_samples=5 * per,
                         dt=two_pi_over(per, omega), record_velocity=True)
    modes = lockin(seg.q[0], seg.phase[0])
    assert np.all(np.abs(modes - z) / np.abs(z) <= 1e-7)
    np.testing.assert_allclose(lockin(seg.v[0], seg.phase[0]), 1j * omega * z, rtol=1e-7)


# ------------------------------------------------------------------ batches and segments
def _batch_systems() -> list[System]:
    cl = Cantilever.rectangular(n_modes=2, quality_factor=150, contact_quality_factors=[50, 80])
    out = []
    for name, a in (("dmt", 1.4), ("visco", 1.2), ("jkr_hysteretic", 1.3), ("none", 1.0),
                    ("dmt+expdamp", 1.6)):
        out.append(System(cl, FORCE_MODELS[name], TipExcitation.for_free_amplitude(cl, 1.0, a)))
    out.append(System(cl, FORCE_MODELS["electrostatic+dmt"],
                      BaseExcitation.for_free_amplitude(cl, 1.0, 1.3)))
    return out


@pytest.mark.parametrize("integrator", [RK4(substeps=3), SolveIVP(rtol=1e-6, atol=1e-9)],
                         ids=["rk4", "solve_ivp"])
def test_batch_equals_individual_runs(integrator) -> None:
    systems = _batch_systems()
    omega = np.array([1.0, 0.98, 1.01, 1.0, 1.02, 0.99])
    gap = np.array([1.0, 0.95, 1.05, 1.0, 1.0, 1.1])
    rate = np.array([0.0, -1e-3, 0.0, 0.0, 2e-4, 0.0])
    periods = 6 if isinstance(integrator, RK4) else 1
    kw = {"n_samples": periods * 40, "dt": two_pi_over(40), "record_velocity": True}
    start = State.free_orbit(systems, omega=omega, gap=gap)
    batch = integrator.run(systems, start, omega=omega, gap_rate=rate, **kw)
    assert batch.contact.any() and not batch.contact.all()
    for i, s in enumerate(systems):
        one = State(start.q[i:i + 1], start.v[i:i + 1], start.contact[i], start.tau[i],
                    start.theta[i], start.gap[i])
        alone = integrator.run(s, one, omega=omega[i], gap_rate=rate[i], **kw)
        for field in ("q", "v", "force", "contact"):
            np.testing.assert_array_equal(getattr(alone, field)[0], getattr(batch, field)[i])
        np.testing.assert_array_equal(alone.work[0], batch.work[i])
        for field in ("q", "v", "contact", "tau", "theta", "gap"):
            np.testing.assert_array_equal(getattr(alone.end, field)[0],
                                          getattr(batch.end, field)[i])


def test_segments_continue_seamlessly() -> None:
    """Two consecutive segments reproduce one long segment (state, regime, phase, work)."""
    t = tapping("jkr_hysteretic")
    start = State.free_orbit(t.system, omega=1.0)
    kw = {"omega": 1.0, "dt": two_pi_over(100), "gap_rate": -2e-4}
    whole = RK4().run(t.system, start, n_samples=1000, **kw)
    first = RK4().run(t.system, start, n_samples=537, **kw)
    second = RK4().run(t.system, first.end, n_samples=463, **kw)
    joined = np.concatenate([first.deflection, second.deflection], axis=1)
    np.testing.assert_allclose(joined, whole.deflection, rtol=0, atol=1e-11)
    np.testing.assert_array_equal(np.concatenate([first.contact, second.contact], axis=1),
                                  whole.contact)
    np.testing.assert_allclose(first.work + second.work, whole.work, rtol=1e-10, atol=1e-13)
    assert second.end.gap[0] == pytest.approx(1.0 - 2e-4 * 1000 * kw["dt"], rel=1e-12)


@pytest.mark.parametrize("integrator", [RK4(), SolveIVP()], ids=["rk4", "solve_ivp"])
def test_start_regime_inconsistent_with_the_gap_is_corrected(integrator) -> None:
    """A hand-built state marked out of contact with the tip inside the sample (z < a0)
    enters the contact branch at once (and the reverse for a tip marked in contact)."""
    t = tapping("dmt")
    for gap, flag, expected in ((0.15, 0, 1), (0.5, 1, 0)):
        state = State(np.zeros((1, 1)), np.zeros((1, 1)), flag, 0.0, 0.0, gap)
        seg = integrator.run(t.system, state, omega=1.0, n_samples=5, dt=1e-3)
        assert np.all(seg.contact[0, 1:] == expected)
        # the force at the first sample after the start is the branch's force
        z = float(seg.gap[0, 1])
        assert seg.force[0, 1] == pytest.approx(float(t.system.force(z, 0.0)), rel=1e-10)


# ------------------------------------------------------------------ invalid inputs
def _free_system() -> System:
    cl = Cantilever.rectangular(n_modes=1, quality_factor=100)
    return System(cl, NoInteraction(), TipExcitation(amplitude=0.01))


INVALID_RUNS = [
    ("dt", {"dt": -0.1}), ("dt", {"dt": 0.0}), ("dt", {"dt": math.nan}),
    ("omega", {"omega": 0.0}), ("omega", {"omega": -1.0}), ("omega", {"omega": math.inf}),
    ("omega", {"omega": [1.0, -1.0]}),
    ("n_samples", {"n_samples": 0}), ("n_samples", {"n_samples": -5}),
    ("gap_rate", {"gap_rate": math.nan}),
    ("systems", {"systems": [_free_system()] * 3}),
    ("systems", {"systems": System(Cantilever.rectangular(n_modes=2, quality_factor=100),
                                   NoInteraction(), TipExcitation(amplitude=0.01))}),
]


@pytest.mark.parametrize("integrator", [RK4(), SolveIVP()], ids=["rk4", "solve_ivp"])
@pytest.mark.parametrize(("param", "change"), INVALID_RUNS,
                         ids=[f"{p}-{i}" for i, (p, _) in enumerate(INVALID_RUNS)])
def test_invalid_run_inputs_raise(integrator, param: str, change: dict) -> None:
    s = _free_system()
    state = State.free_orbit([s, s], omega=1.0)
    kw = {"systems": s, "omega": 1.0, "n_samples": 10, "dt": 0.1, **change}
    with pytest.raises(ValueError, match=rf"^{param}\b"):
        integrator.run(kw.pop("systems"), state, **kw)


@pytest.mark.parametrize(("param", "build"), [
    ("substeps", lambda: RK4(substeps=0)), ("substeps", lambda: RK4(substeps=1.5)),
    ("steps_per_period", lambda: RK4(steps_per_period=4)),
    ("method", lambda: SolveIVP(method="Euler")), ("rtol", lambda: SolveIVP(rtol=0.0)),
    ("atol", lambda: SolveIVP(atol=-1.0)), ("max_step", lambda: SolveIVP(max_step=math.nan)),
])
def test_invalid_integrator_settings_raise(param: str, build) -> None:
    with pytest.raises(ValueError, match=rf"^{param}\b"):
        build()


# ------------------------------------------------------------------ (c) convergence order
PER = 50  # output samples per period
LEVELS = (100, 200, 400, 800, 1600)  # RK4 steps per period


def _rk4_deflection(name: str, steps_per_period: int, periods: int = 20) -> np.ndarray:
    t = tapping(name)
    start = State.free_orbit(t.system, omega=1.0)
    seg = RK4(substeps=steps_per_period // PER).run(t.system, start, omega=1.0,
                                                    n_samples=periods * PER, dt=two_pi_over(PER))
    assert seg.contact.any()
    return seg.deflection[0]


@functools.cache
def convergence_table(name: str) -> tuple[np.ndarray, np.ndarray, float]:
    """Errors vs a 4x finer run at each level, pairwise orders and the least-squares order."""
    err = np.array([np.max(np.abs(_rk4_deflection(name, n) - _rk4_deflection(name, 4 * n)))
                    for n in LEVELS])
    orders = np.log2(err[:-1] / err[1:])
    fitted = -np.polyfit(np.log(LEVELS), np.log(err), 1)[0]
    rows = "\n".join(f"    {n:5d} steps/period  max|dx| {e:.3e}" + (
        f"  order {o:5.2f}" if i else "") for i, (n, e, o) in enumerate(
        zip(LEVELS, err, np.r_[np.nan, orders], strict=True)))
    print(f"\n  RK4 convergence, {name}, 20 periods (vs 4x finer):\n{rows}\n"
          f"    least-squares order {fitted:.2f}")
    return err, orders, fitted


@pytest.mark.parametrize("name", ["dmt_p2", "visco_q1", "dmt_p2.27"])
def test_fourth_order_with_located_events(name: str) -> None:
    """Contact laws that are smooth up to the switching surface (cone p = 2, p = 2.27 in the
    pre-asymptotic range, viscoelastic q = 1): the located events keep RK4 at order 4
    (a step across an unlocated switch would give order 1--2)."""
    err, orders, fitted = convergence_table(name)
    assert np.all(orders > 3.5)
    assert err[-1] < 1e-8


# The force laws below are not smooth at the switching surface: Hertz/DMT F ~ delta**1.5 and
# the viscoelastic term ~ delta**0.5 grow from the contact event like t**1.5 and t**0.5, and the
# JKR force near the neck behaves like F_c + C sqrt(delta - delta_c). Plain RK4 would integrate
# the first/last step of each contact with a local error ~ h**2.5 (Hertz) or h**1.5 (q = 0.5,
# neck). The kernel grades its steps geometrically on the singular side of each switch, which
# removes most of that error: Hertz-type laws converge at ~4th order down to a floor of
# ~1e-7, the sqrt-type laws at >= 2.5 with errors < 1e-6 from 800 steps/period on.
GRADED = {"dmt": 3.8, "jkr": 3.8, "visco": 2.3, "jkr_hysteretic": 2.5}


@pytest.mark.parametrize("name", list(GRADED))
def test_order_for_contact_laws_singular_at_the_event(name: str) -> None:
    """Least-squares order over 100..800 steps/period, and the error level reached."""
    err, _, _ = convergence_table(name)
    fitted = -np.polyfit(np.log(LEVELS[:-1]), np.log(err[:-1]), 1)[0]
    assert fitted > GRADED[name]
    assert err[3] < 1e-6  # 800 steps/period


# ------------------------------------------------------------------ (d) RK4 vs SolveIVP
@functools.cache
def _rk4_vs_solve_ivp(name: str, steps_per_period: int, periods: int = 30):
    t = tapping(name)
    start = State.free_orbit(t.system, omega=1.0)
    kw = {"omega": 1.0, "n_samples": periods * PER, "dt": two_pi_over(PER),
          "record_velocity": True}
    t0 = time.perf_counter()
    ref = SolveIVP(rtol=1e-11, atol=1e-13).run(t.system, start, **kw)
    t_ivp = time.perf_counter() - t0
    t0 = time.perf_counter()
    fast = RK4(substeps=steps_per_period // PER).run(t.system, start, **kw)
    t_rk4 = time.perf_counter() - t0
    amplitude = 0.5 * np.ptp(ref.deflection)  # the transient passes through several regimes
    diff = np.max(np.abs(fast.deflection - ref.deflection))
    dwork = np.max(np.abs(fast.work - ref.work))
    print(f"\n  {name}: RK4 {steps_per_period}/period vs SolveIVP(DOP853, 1e-11), {periods} "
          f"periods: max|dx| = {diff:.2e} = {diff / amplitude:.2e} A (A = {amplitude:.4f}); "
          f"max|dW| = {dwork:.2e}; time RK4 {t_rk4 * 1e3:.1f} ms, SolveIVP {t_ivp:.2f} s")
    return diff, amplitude, fast, ref


@pytest.mark.slow
@pytest.mark.parametrize("name", ["dmt_p2", "visco_q1", "dmt", "visco", "jkr_hysteretic"])
def test_rk4_agrees_with_solve_ivp(name: str) -> None:
    """Every contact law, smooth or weakly singular at the switch, to 1e-6 of the amplitude."""
    diff, amplitude, fast, ref = _rk4_vs_solve_ivp(name, 800)
    assert diff < 1e-6 * amplitude
    assert np.mean(fast.contact != ref.contact) < 2e-3  # only at samples next to an event
    assert np.max(np.abs(fast.work[0, :4] - ref.work[0, :4])) < 1e-5 * ref.work[0, 1]


def test_rk4_agrees_with_solve_ivp_short_run() -> None:
    """Fast-suite version: 3 periods of cone DMT and hysteretic JKR, both integrators."""
    for name, bound in (("dmt_p2", 1e-6), ("jkr_hysteretic", 1e-6)):
        diff, amplitude, fast, ref = _rk4_vs_solve_ivp(name, 800, periods=3)
        assert diff < bound * amplitude
        np.testing.assert_allclose(fast.work[0, 4], ref.work[0, 4], rtol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["dmt", "visco", "jkr_hysteretic"])
def test_solve_ivp_converges_with_tolerance(name: str) -> None:
    """The reference itself: tightening rtol 1e-10 -> 1e-12 changes x by < 5e-8 A."""
    t = tapping(name)
    start = State.free_orbit(t.system, omega=1.0)
    kw = {"omega": 1.0, "n_samples": 10 * PER, "dt": two_pi_over(PER)}
    a = SolveIVP(rtol=1e-10, atol=1e-12).run(t.system, start, **kw).deflection
    b = SolveIVP(rtol=1e-12, atol=1e-14).run(t.system, start, **kw).deflection
    amplitude = 0.5 * np.ptp(b)
    print(f"\n  SolveIVP {name}: |x(1e-10) - x(1e-12)| = {np.max(np.abs(a - b)):.2e}")
    assert np.max(np.abs(a - b)) < 5e-8 * amplitude
