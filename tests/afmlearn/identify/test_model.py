"""IdentifiedModel: compiled force == reference, JSON round trip, simulation vs solve_ivp."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from afmlearn.identify.library import AFMLibrary, Constant, Indentation, InversePower
from afmlearn.identify.model import IdentifiedModel
from simulator import Scales

SC = Scales(spring_constant=20.0, resonance_frequency=3e5, length=1e-8)


def _model(lib=None, coefs=(-8e-6, 1.9), **kw) -> IdentifiedModel:
    lib = lib if lib is not None else AFMLibrary([InversePower(2.0), Indentation(1.5)])
    base = dict(stiffness=1.0, damping=1 / 400, drive_amplitude=1.5 / 400, drive_phase=0.3,
                omega=1.0, a0=0.03, gap=1.0, scales=SC)
    base.update(kw)
    return IdentifiedModel(library=lib, coefficients=np.array(coefs), **base)


def test_force_kernel_matches_reference():
    m = _model()
    z = np.linspace(-0.05, 2.0, 5001)
    zd = np.sin(z * 7)
    np.testing.assert_allclose(m.force(z, zd), m.force_reference(z, zd), rtol=1e-12)


def test_json_roundtrip(tmp_path):
    m = _model(coefficient_bands=np.array([[-9e-6, 1.8], [-7e-6, 2.0]]), info={"a": 1})
    p = m.save(tmp_path / "m.json")
    m2 = IdentifiedModel.load(p)
    assert m2.library.names == m.library.names
    np.testing.assert_array_equal(m2.coefficients, m.coefficients)
    np.testing.assert_array_equal(m2.coefficient_bands, m.coefficient_bands)
    assert m2.equation() == m.equation()
    with pytest.raises(ValueError, match="not an identified model"):
        IdentifiedModel.from_dict({"format": "x"})


def test_free_oscillator_reaches_the_analytic_steady_state():
    """No force: amplitude B / |1 - W^2 + i W D| (driven damped oscillator)."""
    om, d, b = 0.98, 1 / 50, 1 / 50
    m = _model(lib=AFMLibrary([Constant()]), coefs=(0.0,), damping=d, drive_amplitude=b,
               omega=om, drive_phase=0.0)
    dtau = 2 * np.pi / om / 200
    x, _ = m.simulate(0.0, 0.0, tau0=0.0, dtau=dtau, n_samples=200 * 600, substeps=2)
    tail = x[-200 * 20:]
    amp = 0.5 * (tail.max() - tail.min())
    assert amp == pytest.approx(b / abs(1 - om ** 2 + 1j * om * d), rel=2e-4)


def test_simulation_converges_to_solve_ivp_with_contact():
    """Tapping orbit with a DMT-like force: RK4 (fine step) vs scipy's Radau."""
    m = _model(coefs=(-8e-6, 1.9), damping=1 / 100, drive_amplitude=1.3 / 100)
    dtau = 2 * np.pi / 400
    n = 400 * 5
    x, v = m.simulate(1.0, 0.0, tau0=0.0, dtau=dtau, n_samples=n, substeps=8)

    def rhs(t, y):
        f = m.force_reference(np.array([m.gap - y[0]]), np.array([-y[1]]))[0]
        return [y[1], -m.damping * y[1] - y[0] + m.drive_amplitude
                * np.cos(m.omega * t - m.drive_phase) - f]

    t = np.arange(n) * dtau
    ref = solve_ivp(rhs, (0, t[-1]), [1.0, 0.0], t_eval=t, method="DOP853", rtol=1e-10,
                    atol=1e-12, max_step=dtau)
    assert np.max(np.abs(x - ref.y[0])) < 2e-4 * np.ptp(ref.y[0])
    assert np.max(np.abs(v - ref.y[1])) < 2e-3 * np.ptp(ref.y[1])


def test_equation_text_signs_and_empty_force():
    """A negative phase reads ``+ |phi|``; a model without force terms reads ``F_ts = 0``."""
    m = _model(drive_phase=-0.25)
    assert "cos(1 tau + 0.25)" in m.equation()
    assert "cos(1 tau - 0.3)" in _model().equation()
    empty = _model(lib=AFMLibrary([InversePower(2.0)]).subset([False]), coefs=())
    assert "F_ts = 0;" in empty.equation()
    assert "F_ts [N] = 0;" in empty.equation_si()


def test_si_equation_units():
    m = _model()
    terms = {d["term"]: d for d in m.si_terms()}
    # delta^1.5 coefficient: c F / L^1.5  [N m^-1.5]
    assert terms["delta^1.5"]["coefficient"] == pytest.approx(1.9 * SC.force / SC.length ** 1.5)
    assert "m^-1.5" in terms["delta^1.5"]["unit"]
    assert "F_ts [N]" in m.equation_si()


def test_bad_inputs():
    with pytest.raises(ValueError, match="coefficients"):
        _model(coefs=(1.0,))
    with pytest.raises(ValueError, match="n_samples"):
        _model().simulate(0, 0, tau0=0, dtau=0.1, n_samples=0)


def test_no_interaction_model_round_trips(tmp_path):
    """The empty ("no interaction") model saves, loads, evaluates to 0 and simulates."""
    empty = _model(lib=AFMLibrary([InversePower(2.0)]).subset([False]), coefs=())
    m2 = IdentifiedModel.load(empty.save(tmp_path / "m.json"))
    assert m2.library.n_terms == 0
    z = np.linspace(0.1, 2.0, 7)
    np.testing.assert_array_equal(m2.force(z, 0 * z), 0.0)
