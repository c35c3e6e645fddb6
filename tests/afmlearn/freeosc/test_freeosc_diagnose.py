"""diagnose_free on synthetic free oscillations whose cause is known (never shown to it).

~19 samples per period, 1 % detector noise, a 12-bit ADC; the amplitude wanders +-15 % (the
lever arm between an A^n law and a fixed drive), as a self-oscillation's does.
"""

from __future__ import annotations

import numpy as np
import pytest

from afmlearn.freeosc import diagnose_free, simulate_free
from simulator.sensor import DetectorNonlinearity, GaussianNoise, Quantizer, SensorChain


def _sensor(*, a2: float = 0.0, a3: float = 0.0, seed: int = 0) -> SensorChain:
    stages = [DetectorNonlinearity(a2=a2, a3=a3)] if (a2 or a3) else []
    return SensorChain([*stages, GaussianNoise(level=0.01), Quantizer(bits=12, full_scale=2.0)],
                       seed=seed)


def _names(diagnosis) -> list[str]:
    return [c["cause"] for c in diagnosis.causes]


def _case(kind: str, seed: int = 0, **kw):
    if kind == "detector":
        y, fs = simulate_free(n_periods=4000, sensor=_sensor(a2=kw.get("a2", -0.1), a3=0.02,
                                                             seed=seed))
    elif kind == "electrostatic":
        y, fs = simulate_free(n_periods=4000, ac_force=kw.get("ac_force", 0.3),
                              ac_phase_rad=kw.get("ac_phase", 0.3), sensor=_sensor(seed=seed))
    else:
        y, fs = simulate_free(n_periods=4000, sensor=_sensor(seed=seed))
    return diagnose_free(y, sample_rate_hz=fs)


def test_detector_nonlinearity_is_named_and_electrostatic_is_not() -> None:
    d = _case("detector")
    assert d.cause == "detector_nonlinearity"
    assert "electrostatic" not in _names(d)
    assert d.gain > 0.3
    ev = d.evidence
    assert ev["scaling"]["h2"]["exponent"] == pytest.approx(2.0, abs=0.3)
    assert ev["dc_coupling"]["slope"] == pytest.approx(1.0, abs=0.3)  # not -3 (a force)
    assert ev["phase_lock"]["h2"]["offset_from_real_rad"] < 0.02


def test_electrostatic_second_harmonic_drive_is_named_and_detector_is_not() -> None:
    d = _case("electrostatic")
    assert d.cause == "electrostatic"
    assert "detector_nonlinearity" not in _names(d)
    assert d.gain > 0.3
    best = max(d.candidates, key=lambda c: c["gain"])
    assert best["model"] == "AcBiasDrive" and not best["excluded"]
    assert abs(d.evidence["scaling"]["h2"]["exponent"]) < 0.3  # fixed drive: A^0


def test_clean_lever_names_no_cause() -> None:
    d = _case("clean")
    assert d.cause == "none"
    assert d.causes == []
    assert all(abs(c["gain"]) < 0.02 for c in d.candidates)
    assert d.evidence["relative_harmonics"][1] < 2e-3


def test_report_is_json_ready_and_model_predicts_the_record() -> None:
    from afmlearn.io import jsonable
    y, fs = simulate_free(n_periods=1500, modulation_periods=500.0,
                          sensor=_sensor(a2=-0.1, seed=3))
    d = diagnose_free(y, sample_rate_hz=fs, block_periods=100)
    report = jsonable(d.to_dict())
    assert report["cause"] == d.cause
    assert set(report) >= {"baseline", "extended", "gain", "candidates", "causes", "evidence"}
    pred = d.predict()
    v = d.demod.valid
    assert np.std(pred[v] - y[v]) < 0.5 * np.std(d.demod.fundamental()[v] - y[v])


def test_bad_input_raises_naming_the_parameter() -> None:
    y, fs = simulate_free(n_periods=200, modulation_periods=100.0)
    with pytest.raises(ValueError, match="heldout_fraction"):
        diagnose_free(y, sample_rate_hz=fs, heldout_fraction=0.95)
    with pytest.raises(ValueError, match="min_gain"):
        diagnose_free(y, sample_rate_hz=fs, min_gain=1.5)
    with pytest.raises(ValueError, match="n_harmonics"):
        diagnose_free(y, sample_rate_hz=fs, n_harmonics=12)
    with pytest.raises(ValueError, match="20 periods"):
        diagnose_free(y[:300], sample_rate_hz=fs)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_naming_over_seeds_signs_and_phases(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a2 = float(rng.choice([-1, 1]) * rng.uniform(0.03, 0.15))
    d = _case("detector", seed=seed, a2=a2)
    assert d.cause == "detector_nonlinearity" and "electrostatic" not in _names(d)
    e = _case("electrostatic", seed=seed, ac_force=float(rng.uniform(0.1, 0.5)),
              ac_phase=float(rng.uniform(-np.pi, np.pi)))
    assert e.cause == "electrostatic" and "detector_nonlinearity" not in _names(e)
    assert _case("clean", seed=seed).cause == "none"
