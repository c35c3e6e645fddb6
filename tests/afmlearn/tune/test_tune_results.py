"""The best settings are exported as a Hydra config an entry point composes with
``+experiment=<study>``; the summary counts every state."""

from __future__ import annotations

from pathlib import Path

import optuna
from hydra import compose, initialize_config_dir

from afmlearn.tune import summary, summary_table, write_results

CONF = str(Path(__file__).parents[3] / "conf")


def _study() -> optuna.Study:
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name="id_rec", direction="maximize",
                                sampler=optuna.samplers.RandomSampler(seed=1))

    def objective(trial: optuna.Trial) -> float:
        n_a0 = trial.suggest_int("identifier.n_a0", 4, 20)
        refine = trial.suggest_categorical("identifier.refine", [True, False])
        group = trial.suggest_categorical("identifier", ["fast", "default"])
        if n_a0 > 18:
            raise optuna.TrialPruned()
        return -abs(n_a0 - 9) + 0.5 * refine + 0.1 * (group == "fast")

    study.optimize(objective, n_trials=12)
    return study


def test_best_settings_compose_as_an_experiment(tmp_path: Path) -> None:
    study = _study()
    files = write_results(study, results_dir=tmp_path, groups=["identifier"])
    best = study.best_trial.params
    text = files["experiment"].read_text()
    assert text.startswith("# @package _global_")
    with initialize_config_dir(CONF, version_base="1.3"):
        cfg = compose("identify", overrides=[f"hydra.searchpath=[file://{tmp_path}]",
                                             "+experiment=id_rec", "trace=x.h5"])
    assert cfg.identifier.n_a0 == best["identifier.n_a0"]
    assert cfg.identifier.refine == best["identifier.refine"]
    # the group choice arrives through the defaults list: fast sets n_bootstrap 8
    assert (cfg.identifier.n_bootstrap == 8) == (best["identifier"] == "fast")
    assert "best_params" in files["best"].read_text()


def test_summary_counts_states() -> None:
    study = _study()
    doc = summary(study)
    states = [t.state for t in study.trials]
    assert doc["counts"]["complete"] == states.count(optuna.trial.TrialState.COMPLETE)
    assert doc["counts"]["pruned"] == states.count(optuna.trial.TrialState.PRUNED)
    assert doc["best"]["number"] == study.best_trial.number
    table = summary_table(study)
    assert table.splitlines()[3].split()[0] == str(study.best_trial.number)  # best row first


def test_figures_are_written(tmp_path: Path) -> None:
    from afmlearn.plots.tune import write_figures

    files = write_figures(_study(), tmp_path)
    assert set(files) == {"history", "importances", "parallel"}
    for path in files.values():
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
