"""The compiled diagnosis kernel against its plain-Python twin, and physics of its orbits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afmlearn.diagnose._kernel import simulate_model, simulate_reference
from afmlearn.diagnose.hypotheses.adhesion_hysteresis import Neck
from afmlearn.diagnose.hypotheses.higher_mode import SecondMode
from afmlearn.diagnose.hypotheses.viscoelastic import ViscoelasticTerm
from afmlearn.diagnose.model import DiagnosisModel
from afmlearn.diagnose.output_error import periodic_orbit
from afmlearn.diagnose.spec import ModelSpec
from simulator import Scales

SCALES = Scales(spring_constant=20.0, resonance_frequency=3e5, length=1e-8)


def _model(*extensions) -> DiagnosisModel:
    s = ModelSpec(a0=0.03, drive_phase=0.3, extensions=extensions)
    n = s.n_force
    coef = np.zeros(3 + n)
    coef[:3] = [1.0, 1 / 300, 0.009]
    coef[3:5] = [-5e-5, 2.3]
    if s.get(ViscoelasticTerm) is not None:
        coef[5] = 0.2
    if s.neck is not None:
        coef[-1] = 0.4
    return DiagnosisModel(spec=s, coef=coef, omega=1.0, gap=1.0, scales=SCALES)


class _Force:
    def __init__(self, m: DiagnosisModel) -> None:
        self.m, self.a0 = m, m.spec.a0
        self.dc = m.spec.neck.neck_length() if m.spec.neck is not None else 0.0

    def __call__(self, z, zd, att):
        return float(self.m.force(np.array([z]), np.array([zd]), np.array([att]))[0])


@pytest.mark.parametrize("spec", [(), (ViscoelasticTerm(0.5),), (Neck(0.05),),
                                  (SecondMode(6.1, 900.0, 1.0),)], ids=str)
def test_kernel_matches_reference(spec):
    m = _model(*spec)
    args = m.kernel_args()
    s0 = np.array([0.9, 0.4, 0.0, 0.0])
    dt = 2 * math.pi / 200
    fast, _, _ = simulate_model(s0, False, 0.0, dt, 400, 2, *args)
    ref = simulate_reference(s0, False, 0.0, dt, 400, 2, args[0], _Force(m))
    assert np.max(np.abs(fast - ref)) < 1e-10


def _settled(m: DiagnosisModel) -> np.ndarray:
    """State at tau = 0 after 3000 periods from the free orbit's start."""
    x, v = m.simulate(np.array([0.0, 2.7, 0.0, 0.0]), attached0=False, tau0=0.0, dtau=0.01,
                      n_samples=1, substeps=1, settle_periods=3000)
    return np.array([x[0], v[0], 0.0, 0.0])


def test_conservative_orbit_balances_drive_and_damping():
    """On a periodic orbit of a conservative force, drive input = lever damping."""
    m = _model()
    x, v, ok = periodic_orbit(m, _settled(m), False, n_out=2048)
    assert ok
    tau = np.arange(x.size) * 2 * math.pi / x.size
    drive = m.coef[2] * np.cos(tau - m.spec.drive_phase)
    e_in = np.mean(drive * v) * 2 * math.pi
    e_damp = np.mean(m.coef[1] * v**2) * 2 * math.pi
    assert abs(e_in - e_damp) < 1e-6 * e_in


def test_neck_loss_is_the_loop_area_and_converges_with_the_step():
    """The JKR neck takes the area between its pull and the tail per cycle; switches are
    located, so the orbit converges with the step count (a fixed step through a switch would
    make it first order). The JKR force is ``F_c + C sqrt(delta - delta_c)`` at the neck's
    stability limit (unbounded stiffness, steps not graded here), which caps the order at
    ~1.5 (measured: 1.9e-5, 2.7e-6, 4.3e-7 at 256, 1024, 4096 steps against 16384)."""
    m = _model(Neck(0.05))
    orbits = []
    s0 = _settled(m)
    for n in (256, 1024, 4096):
        x, v, ok = periodic_orbit(m, s0, False, n_out=n)
        assert ok
        orbits.append(np.fft.rfft(x)[:8] / n)
    assert np.max(np.abs(orbits[0] - orbits[2])) < 3e-5
    assert np.max(np.abs(orbits[1] - orbits[2])) < 4e-6
    # energy into the sample = drive input - damping (one period, fine grid)
    tau = np.arange(x.size) * 2 * math.pi / x.size
    drive = m.coef[2] * np.cos(tau - m.spec.drive_phase)
    e_ts = np.mean(drive * v - m.coef[1] * v**2) * 2 * math.pi
    a0, dc = m.spec.a0, m.spec.neck.neck_length()
    zq = np.linspace(a0, a0 + dc, 20001)
    area = -0.4 * np.trapezoid(m.spec.neck.column(zq, np.ones(zq.size, bool), a0), zq)
    assert area > 0 and e_ts == pytest.approx(area, rel=2e-3)


def _neck_state_reference(z, a0, neck_length):
    """Plain-Python twin of the compiled neck state (attach at z <= a0, snap past a0 + d_c,
    the period swept twice)."""
    out, on = np.zeros(z.size, bool), False
    for sweep in range(2):
        for i, zi in enumerate(z):
            if zi <= a0:
                on = True
            elif zi > a0 + neck_length:
                on = False
            if sweep:
                out[i] = on
    return out


def _invert_reference(y, coefficients):
    """Plain NumPy twin of the compiled detector inverse: Newton on every sample at once."""
    x = np.array(y, float)
    for _ in range(30):
        g = x
        d = 1.0
        for k, b in enumerate(coefficients, start=2):
            g = g + b * x**k
            d = d + float(k) * b * x ** (k - 1)
        g = g - y
        d = np.where(np.abs(d) < 0.2, np.sign(d) * 0.2 + (d == 0) * 0.2, d)
        step = g / d
        x -= step
        if np.max(np.abs(step)) < 1e-13:
            break
    return x


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_neck_state_matches_reference(seed):
    from afmlearn.diagnose._kernel import neck_state
    rng = np.random.default_rng(seed)
    th = np.linspace(0.0, 2 * np.pi, 401, endpoint=False)
    z = 0.05 + rng.uniform(0.9, 1.2) * (1 + np.cos(th + rng.uniform(0, 2 * np.pi)))
    z = z + 0.01 * rng.standard_normal(z.size)          # chatter around the switches
    a0, dc = rng.uniform(0.02, 0.08), rng.uniform(0.0, 0.3)
    got = neck_state(z, a0, dc)
    assert got.dtype == np.bool_ and got.shape == z.shape
    assert np.array_equal(got, _neck_state_reference(z, a0, dc))
    # a period that never touches is never attached, one always in contact always is
    assert not neck_state(z + 5.0, a0, dc).any()
    assert neck_state(np.full(7, a0), a0, dc).all()


@pytest.mark.parametrize("coefficients", [(0.03, -0.01), (-0.06, 0.02, 0.002), (0.05,),
                                          (0.0, 0.0)])
def test_compiled_detector_inverse_matches_reference(coefficients):
    from afmlearn.diagnose._kernel import invert_polynomial
    x = np.linspace(-1.5, 1.5, 301)
    b = np.asarray(coefficients, float)
    y = x + sum(c * x ** (k + 2) for k, c in enumerate(b))
    got = invert_polynomial(y, b)
    # the twin stops when every sample's step is small, the kernel sample by sample
    assert np.allclose(got, _invert_reference(y, b), rtol=0, atol=1e-13)
    assert np.allclose(got, x, rtol=0, atol=1e-11)     # the map is monotone on this range


@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_bvls_matches_scipy(seed):
    """The compiled BVLS on the QR-reduced problem against SciPy's ``lsq_linear(method=
    "bvls")`` on the full one: free, one-sided and boxed coefficients, bounds active or
    not, columns scaled over seven decades (unit-norm scaling as ``bounded_lstsq`` does)."""
    from scipy.optimize import lsq_linear

    from afmlearn.diagnose._kernel import bvls
    rng = np.random.default_rng(seed)
    active = 0
    for _ in range(300):
        m, p = int(rng.integers(20, 300)), int(rng.integers(1, 10))
        A = rng.standard_normal((m, p)) * 10 ** rng.uniform(-4, 3, p)
        b = 3 * rng.standard_normal(m)
        lo = np.where(rng.uniform(size=p) < 0.5, -np.inf, rng.uniform(-1, 0.2, p))
        width = rng.uniform(0.3, 1.5, p)
        hi = np.where(rng.uniform(size=p) < 0.5, np.inf, np.where(np.isfinite(lo), lo + width,
                                                                  width))
        scale = np.linalg.norm(A, axis=0)
        As, lo, hi = A / scale, lo * scale, hi * scale
        ref = lsq_linear(As, b, bounds=(lo, hi), method="bvls", lsmr_tol="auto").x
        Rb = np.linalg.qr(np.column_stack([As, b]), mode="r")
        x = bvls(np.ascontiguousarray(Rb[:p, :p]), Rb[:p, p].copy(), float(Rb[p, p] ** 2),
                 lo, hi)
        assert np.all((x >= lo) & (x <= hi))
        assert np.allclose(x, ref, rtol=1e-10, atol=1e-10 * max(1.0, np.abs(ref).max()))
        active += bool(np.any(np.isclose(ref, lo) | np.isclose(ref, hi)))
    assert active > 100          # the bounds were active on many of the problems


def test_bvls_keeps_scipys_answer_on_a_rank_deficient_design():
    """Two equal columns: the cost reaches SciPy's minimum (the split between them is not
    unique)."""
    from scipy.optimize import lsq_linear

    from afmlearn.diagnose.balance import bounded_lstsq
    rng = np.random.default_rng(3)
    A = rng.standard_normal((200, 4))
    A = np.column_stack([A, A[:, 1]])
    b = rng.standard_normal(200)
    lo, hi = np.r_[-np.inf, 0.0, -np.inf, 0.0, 0.0], np.full(5, np.inf)
    P, t = np.zeros((1, 5)), np.zeros(1)
    coef, r = bounded_lstsq(A, b, P, t, lo, hi)
    ref = lsq_linear(A, b, bounds=(lo, hi), method="bvls").x
    assert r @ r == pytest.approx(np.sum((A @ ref - b) ** 2), rel=1e-12)
    assert np.all(coef >= lo)
