"""Lennard-Jones cantilever of dissertation ch. 2 (Table 2.1): linear frequencies of the two
attractors measured from simulated ring-downs, against the published values.

The dissertation normalises by the *equilibrium* gap eta* (static deflection included), so the
undeflected rest gap is ``1 + x_eq`` with ``x_eq = C_att - C_rep`` (force balance at z = 1).
Published: attractive-regime natural frequency 0.83, in-contact attractor 3.72.
"""

import numpy as np
import pytest
from scipy.optimize import brentq

from simulator import Cantilever, Scales, State, System, TipExcitation
from simulator.forces import LennardJones
from simulator.integrate import RK4

K, F1, ETA = 0.11, 11.804e3, 6.542e-9
A1, A2, R = 1.35961e-70, 1.8651e-19, 150e-9


@pytest.fixture(scope="module")
def lj():
    return LennardJones.from_si(a1_jm6=A1, a2_j=A2, tip_radius_m=R,
                                scales=Scales(K, F1, ETA))


def test_dimensionless_coefficients(lj):
    assert lj.attraction == pytest.approx(A2 * R / (6 * K * ETA**3), rel=1e-12)
    assert lj.attraction == pytest.approx(0.1514, abs=5e-4)
    assert lj.repulsion == pytest.approx(4.69e-5, rel=5e-3)


def ringdown_frequency(lj, gap, z_eq):
    """Free (undriven, undamped) small oscillation about the equilibrium at gap z_eq."""
    cl = Cantilever(stiffness=[1.0], damping=[0.0])
    s = System(cl, lj, TipExcitation(amplitude=0.0))
    x_eq = gap - z_eq
    st = State(q=[[x_eq + 1e-4 * z_eq]], v=[[0.0]], contact=0, tau=0.0, theta=0.0, gap=gap)
    n, dt = 40000, 0.005
    seg = RK4(substeps=4).run(s, st, omega=1.0, n_samples=n, dt=dt)
    x = seg.deflection[0] - x_eq
    up = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    t = (up + x[up] / (x[up] - x[up + 1])) * dt  # interpolated upward zero crossings
    return 2 * np.pi / np.mean(np.diff(t))


def test_attractor_frequencies_match_dissertation(lj):
    ca, cr = lj.attraction, lj.repulsion
    gap = 1.0 + (ca - cr)  # undeflected gap whose static equilibrium is z = 1

    def balance(z):  # x = -F_ts(z) with x = gap - z
        return (gap - z) + (cr / z**8 - ca / z**2)

    w_att = ringdown_frequency(lj, gap, 1.0)
    z_c = brentq(balance, 0.2, 0.4)  # in-contact (repulsive) equilibrium
    w_rep = ringdown_frequency(lj, gap, z_c)
    # analytic linearisation: omega^2 = 1 - dF/dz
    for w, z in ((w_att, 1.0), (w_rep, z_c)):
        assert w**2 == pytest.approx(1 + 8 * cr / z**9 - 2 * ca / z**3, rel=1e-4)
    assert w_att == pytest.approx(0.83, abs=0.01)
    assert w_rep == pytest.approx(3.72, rel=0.05)  # published 3.72; sensitive to z_c
