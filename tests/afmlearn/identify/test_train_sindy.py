"""afmlearn.identify.train: simulate + identify + score, truth mapping, unit handling."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from afmlearn.identify.library import (
    AFMLibrary,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
)
from afmlearn.identify.model import IdentifiedModel
from afmlearn.identify.train import match_terms, score, train, true_model
from afmlearn.plots.identify import training_figures
from simulator import Scales

ROOT = Path(__file__).resolve().parents[3]
TINY = ["identifier=fast", "noise.level=0.005", "free_trace_periods=5",
        "scenarios.steady.n_periods=25", "scenarios.steady.samples_per_period=100",
        "scenarios.transient.periods_before=5", "scenarios.transient.periods_after=20",
        "scenarios.transient.samples_per_period=100"]


def compose_train(*overrides: str):
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        return compose("train_sindy", overrides=list(overrides))


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("train")
    cfg = compose_train(*TINY, f"output_dir={out}")
    metrics, objects = train(cfg, figures=training_figures)
    return metrics, objects, out


def test_config_composes_every_group():
    cfg = compose_train()
    assert cfg.identifier._target_ == "afmlearn.identify.identifier.ForceIdentifier"
    assert cfg.identifier.n_folds >= 10
    assert cfg.scenarios.steady._target_ == "simulator.scenarios.SteadyState"
    assert cfg.scenarios.transient._target_ == "simulator.scenarios.Transient"
    assert list(cfg.train.scenarios) == ["steady", "transient"]
    assert cfg.force._target_ == "simulator.forces.DMT.from_si"
    fast = compose_train("identifier=fast", "force=dmt_visco", "noise.level=0.02")
    assert (fast.identifier.n_folds, fast.identifier.n_a0, fast.identifier.n_bootstrap,
            fast.identifier.max_terms) == (4, 6, 8, 3)
    assert fast.force._target_ == "simulator.forces.ViscoelasticDMT.from_si"
    assert fast.noise.level == 0.02


@pytest.mark.slow  # simulate + identify two scenarios with figures: ~20 s of CPU
def test_train_writes_metrics_models_and_figures(trained):
    metrics, objects, out = trained
    doc = json.loads((out / "metrics.json").read_text())
    assert set(doc["scenarios"]) == {"steady", "transient"}
    for name in ("steady", "transient"):
        for key in ("force_accuracy_whole", "force_accuracy_repulsive", "state_accuracy",
                    "coef_max_rel_error", "drive_rel_error", "support_exact", "n_terms"):
            assert f"{name}/{key}" in metrics
        folder = out / name
        for f in ("trace.h5", "model.json", "result.json", "pareto.png", "coefficients.png",
                  "orbit.png", "force.png"):
            assert (folder / f).stat().st_size > 0, f
        run = objects["runs"][name]
        model = IdentifiedModel.load(folder / "model.json")
        ide = run["identifier"]
        assert model.equation() == ide.model_.equation()
        z = np.linspace(0.5 * model.a0, 1.5, 50)
        zd = np.full_like(z, 0.01)
        np.testing.assert_allclose(model.force(z, zd), ide.model_.force(z, zd))
        rec = doc["scenarios"][name]
        assert rec["terms"]["true"] == ["z^-2", "delta^1.5"]
        assert "force_error" in ide.candidates_[0].scores   # truth fed the Pareto front
        assert "force_error" in ide.objectives_
    # the transient is not periodic: the weak form is used
    assert not objects["runs"]["transient"]["identifier"].periodic_


@pytest.mark.slow
def test_train_metrics_are_physical(trained):
    """Constraint boxes hold and the identified force is close to the truth (loose bounds)."""
    metrics, objects, _ = trained
    for name in ("steady", "transient"):
        assert metrics[f"{name}/stiffness_error"] <= 0.15 + 1e-9      # K box +-15 %
        assert metrics[f"{name}/damping_rel_error"] <= 0.15 + 1e-9    # D box
        assert metrics[f"{name}/drive_rel_error"] <= 0.16             # B box (F_c estimated)
        assert metrics[f"{name}/state_accuracy"] > 0.8
        assert metrics[f"{name}/force_accuracy_whole"] > 0.7
        # accuracy = 1 - NRMSE over the whole trace, normalised by the true range
        rec = objects["runs"][name]["record"]
        assert rec["force_accuracy"]["whole"]["accuracy"] == pytest.approx(
            metrics[f"{name}/force_accuracy_whole"])


def test_unknown_scenario_is_a_value_error(tmp_path):
    cfg = compose_train(*TINY, "train.scenarios=[nope]", f"output_dir={tmp_path}")
    with pytest.raises(ValueError, match="train.scenarios: 'nope' has no node scenarios.nope"):
        train(cfg)


# ---------------------------------------------------------------------------- truth mapping
SCALES = Scales(spring_constant=20.68, resonance_frequency=259.9e3, length=10e-9)


def labels_model(force: dict) -> dict:
    return {"force": force, "excitation": {"kind": "tip", "amplitude": 0.0034},
            "calibration": {"spring_constant_n_per_m": SCALES.spring_constant,
                            "resonance_frequency_hz": SCALES.resonance_frequency,
                            "length_m": SCALES.length}}


DMT = {"model": "dmt", "parameters": {"a0": 0.03, "vdw": 8e-6, "stiffness": 1.93,
                                      "exponent": 1.5}}
VISCO = {"model": "dmt_visco", "parameters": {**DMT["parameters"], "viscosity": 0.7,
                                              "viscosity_exponent": 0.5}}
EXPD = {"model": "expdamp", "parameters": {"coefficient": 0.3, "decay_length": 0.2}}
LJ = {"model": "lj", "parameters": {"repulsion": 1e-12, "attraction": 3e-6}}


@pytest.mark.parametrize("force, expected", [
    (DMT, {"z^-2": -8e-6, "delta^1.5": 1.93}),
    (VISCO, {"z^-2": -8e-6, "delta^1.5": 1.93, "delta^0.5 delta'": 0.7}),
    ({"model": "dmt+expdamp", "parameters": {"terms": [DMT, EXPD]}},
     {"z^-2": -8e-6, "delta^1.5": 1.93, "exp(-z/0.2) z'": -0.3}),
    (LJ, {"z^-8": 1e-12, "z^-2": -3e-6}),
])
def test_true_model_maps_simulator_parameters(force, expected):
    m = true_model(labels_model(force), omega=1.0, quality_factor=443.0)
    assert dict(zip(m.library.names, m.coefficients, strict=True)) == pytest.approx(expected)
    assert m.damping == pytest.approx(1 / 443) and m.drive_amplitude == 0.0034
    if force is LJ:  # a0 of LJ: the zero of the force, (repulsion / attraction)^(1/6)
        assert m.a0 == pytest.approx((1e-12 / 3e-6) ** (1 / 6))
        z = np.array([m.a0])
        assert abs(1e-12 * z[0] ** -8 - 3e-6 * z[0] ** -2) < 1e-9 * 3e-6 * z[0] ** -2


def test_unmapped_models_have_no_truth():
    assert true_model(labels_model({"model": "jkr_hysteretic", "parameters": {}}), omega=1.0,
                      quality_factor=443.0) is None


def rescaled(model: IdentifiedModel, s: float) -> IdentifiedModel:
    """The same physical model in the length unit L' = s L (plain reference conversion).

    F / (k L) = c theta with theta ~ length^a (a rate counts as a length) gives
    c' = c s^(a - 1); decay lengths, a0, the gap and the drive amplitude scale as 1/s.
    """
    terms, coefs = [], []
    for t, c in zip(model.library.terms, model.coefficients, strict=True):
        if isinstance(t, InversePower):
            a = -t.n
        elif isinstance(t, Indentation):
            a = t.p
        elif isinstance(t, IndentationRate):
            a = t.p + t.l                       # a rate is a length per unit time
        else:
            assert isinstance(t, ExponentialDamping)
            a, t = 1, ExponentialDamping(t.decay_length / s)
        terms.append(t)
        coefs.append(c * s ** (a - 1))
    sc = Scales(spring_constant=model.scales.spring_constant,
                resonance_frequency=model.scales.resonance_frequency,
                length=model.scales.length * s)
    return IdentifiedModel(library=AFMLibrary(terms), coefficients=np.array(coefs),
                           stiffness=model.stiffness, damping=model.damping,
                           drive_amplitude=model.drive_amplitude / s, drive_phase=0.0,
                           omega=model.omega, a0=model.a0 / s, gap=model.gap / s, scales=sc)


class FakeIdentifier:
    """What score() reads from a fitted ForceIdentifier."""

    def __init__(self, model: IdentifiedModel, force: np.ndarray) -> None:
        self.model_ = model
        self.force_ = force
        self.summary_ = {"state_accuracy_heldout": 0.99,
                         "interaction_exponent": next(
                             t.p for t in model.library.terms if isinstance(t, Indentation))}
        self.warnings_: list[str] = []


def test_score_is_unit_independent():
    """The truth re-expressed in another length unit (a transient's L_ref) scores perfectly."""
    force = {"model": "dmt+expdamp", "parameters": {"terms": [VISCO, EXPD]}}
    lab = labels_model(force)
    truth = true_model(lab, omega=1.0, quality_factor=443.0)
    est = rescaled(truth, 0.8)
    # the rescaled model is the same physics: same force in newtons at the same gap
    z_m = np.linspace(0.1e-9, 12e-9, 200)
    zd = np.full_like(z_m, -0.3) * SCALES.length * SCALES.omega0
    np.testing.assert_allclose(est.force_si(z_m, zd), truth.force_si(z_m, zd), rtol=1e-10)
    assert match_terms(est, truth) == {0: 0, 1: 1, 2: 2, 3: 3}
    f_true = truth.force(z_m / SCALES.length, zd / (SCALES.length * SCALES.omega0))
    f_n = f_true * SCALES.force
    rec = score(FakeIdentifier(est, f_n / est.scales.force), truth, force_n=f_n, gap_m=z_m,
                model_json=lab, scales=est.scales)
    assert rec["coefficients"]["max_rel_error"] == pytest.approx(0.0, abs=1e-10)
    assert rec["terms"]["support_exact"] and rec["terms"]["spurious"] == []
    assert rec["force_accuracy"]["whole"]["accuracy"] == pytest.approx(1.0)
    assert rec["exponent"]["error"] == 0.0
    assert rec["lever"]["drive_rel_error"] == pytest.approx(0.0, abs=1e-12)
    assert set(rec["truth_si_by_est"]) == set(est.library.names)


def test_score_counts_wrong_exponent_as_missing_and_spurious():
    lab = labels_model(DMT)
    truth = true_model(lab, omega=1.0, quality_factor=443.0)
    est = IdentifiedModel(library=AFMLibrary([InversePower(2.0), Indentation(2.5)]),
                          coefficients=np.array([-8e-6 * 1.1, 5.0]), stiffness=1.0,
                          damping=1 / 443, drive_amplitude=0.0034, drive_phase=0.0, omega=1.0,
                          a0=0.03, gap=1.0, scales=SCALES)
    z = np.linspace(0.01, 1.5, 100)
    rec = score(FakeIdentifier(est, est.force(z, 0 * z)), truth,
                force_n=truth.force(z, 0 * z) * SCALES.force, gap_m=z * SCALES.length,
                model_json=lab, scales=SCALES)
    assert rec["terms"]["missing"] == ["delta^1.5"]
    assert rec["terms"]["spurious"] == ["delta^2.5"]
    assert not rec["terms"]["support_exact"]
    assert rec["coefficients"]["terms"]["z^-2"]["rel_error"] == pytest.approx(0.1)
    assert rec["exponent"]["error"] == pytest.approx(1.0)
    assert math.isfinite(rec["force_nrmse"])
