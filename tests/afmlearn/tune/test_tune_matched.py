"""Experiments matched to a recording: calibration read back, matched simulator config, the
identifier scored per experiment and pruned between experiments."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import optuna
import pytest
from hydra import compose, initialize_config_dir

import afmlearn.tune.matched as matched
from afmlearn.io import read_trace
from afmlearn.simulate import simulate
from afmlearn.tune import open_storage, open_study, running

CONF = str(Path(__file__).parents[3] / "conf")


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short noisy 'recording' on a lever unlike the default one (k, f0, Q, drive, noise)."""
    out = tmp_path_factory.mktemp("rec") / "rec.h5"
    with initialize_config_dir(CONF, version_base="1.3"):
        cfg = compose("simulate", overrides=[
            "cantilever.spring_constant_n_per_m=40.0", "cantilever.resonance_frequency_hz=3.0e5",
            "cantilever.quality_factor=300", "scenario.n_periods=40",
            "scenario.samples_per_period=100", "scenario.omega=1.002", "noise.level=0.03",
            "excitation.free_amplitude_ratio=1.2", "progress=false", "seed=3",
            f"output={out}"])
    simulate(cfg)
    return out


def _tune_cfg(recording: Path, tmp: Path, *extra: str):
    with initialize_config_dir(CONF, version_base="1.3"):
        return compose("tune", overrides=[f"recording={recording}", "identifier=fast",
                                          f"matched.cache_dir={tmp}", *extra])


def test_calibration_is_read_back_without_labels(recording: Path, monkeypatch) -> None:
    calls = []

    def spy(path, **kwargs):
        calls.append(kwargs)
        return read_trace(path, **kwargs)

    monkeypatch.setattr(matched, "read_trace", spy)
    cal = matched.recording_calibration(recording)
    assert calls and not any(kw.get("labels") for kw in calls)
    assert cal["spring_constant_n_per_m"] == 40.0 and cal["quality_factor"] == 300.0
    assert cal["resonance_frequency_hz"] == 3.0e5
    assert cal["omega"] == pytest.approx(1.002)
    assert cal["samples_per_period"] == pytest.approx(100.0)
    assert cal["n_periods"] == pytest.approx(40.0)
    assert cal["free_amplitude_m"] == pytest.approx(1.2 * cal["gap_m"])
    # tapping: the set-point amplitude is below the free one; the white-noise std is recovered
    assert 0.3 * cal["free_amplitude_m"] < cal["amplitude_m"] < cal["free_amplitude_m"]
    assert cal["noise_level"] == pytest.approx(0.03, rel=0.1)


def test_matched_config_copies_the_recording(recording: Path, tmp_path: Path) -> None:
    cfg = _tune_cfg(recording, tmp_path)
    cal = matched.recording_calibration(recording)
    sim = matched.matched_config(cfg, cal)
    assert sim.cantilever.spring_constant_n_per_m == 40.0
    assert sim.scales.spring_constant == 40.0  # interpolations follow (units of the truth)
    assert sim.scales.resonance_frequency == 3.0e5
    assert sim.cantilever.quality_factor == 300.0
    assert sim.scenario.samples_per_period == 100 and sim.scenario.n_periods == 40
    assert sim.excitation.free_amplitude_ratio == pytest.approx(1.2)
    assert sim.noise.level == pytest.approx(cal["noise_level"])
    assert sim.shard.count == 3 and "reduced_modulus_pa" in sim.dataset.ranges.force
    again = matched.matched_config(cfg, cal)
    other = matched.matched_config(_tune_cfg(recording, tmp_path, "matched.seed=5"), cal)
    assert again.output == sim.output != other.output  # cache keyed by the whole config
    with pytest.raises(ValueError, match="excitation"):
        matched.matched_config(_tune_cfg(recording, tmp_path, "excitation=base"), cal)


@pytest.mark.slow
def test_evaluate_scores_each_experiment_and_is_pruned_between(recording: Path,
                                                              tmp_path: Path) -> None:
    cfg = _tune_cfg(recording, tmp_path, "matched.n_experiments=2")
    metrics, objects = matched.evaluate(cfg)
    acc = [metrics["force_accuracy_0"], metrics["force_accuracy_1"]]
    assert metrics["force_accuracy"] == pytest.approx(np.mean(acc))
    assert all(0.5 < a <= 1.0 for a in acc)  # a DMT force the identifier can find
    for path in objects["experiments"]:
        labels = read_trace(path, labels=True).labels
        assert labels.model["calibration"]["spring_constant_n_per_m"] == 40.0
    # inside a study whose pruner stops anything below 0.999: pruned after experiment 0
    storage = open_storage(f"sqlite:///{tmp_path / 's.db'}", heartbeat_interval=5)
    study = open_study(storage, study_name="s", directions=["maximize"],
                       pruner=optuna.pruners.ThresholdPruner(lower=0.999))
    trial = study.ask()
    with running(trial), pytest.raises(optuna.TrialPruned):
        matched.evaluate(cfg)
    assert list(study.trials[0].intermediate_values) == [0]
