"""QRNN trials under the sweeper report val/loss per epoch and are pruned through
optuna-integration's Lightning callback (scripts/train_qrnn.py -m hparams_search=qrnn)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import optuna
import pytest
from optuna.trial import TrialState

ROOT = Path(__file__).parents[3]


@pytest.mark.slow
def test_qrnn_trials_are_pruned_per_epoch(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'q.db'}"
    cmd = [sys.executable, str(ROOT / "scripts" / "train_qrnn.py"), "-m", "hparams_search=qrnn",
           "experiment=qrnn_smoke", "data=qrnn_tiny", "trainer.max_epochs=3",
           f"paths.root_dir={tmp_path}", "hydra.sweeper.n_trials=3",
           f"hydra.sweeper.storage={url}", f"hydra.sweeper.results_dir={tmp_path / 'tuned'}",
           f"hydra.sweep.dir={tmp_path / 'multirun'}", "callbacks.progress_bar.refresh_rate=0",
           # a pruner that keeps trials whose first epoch is below the median of val/loss
           # at that epoch: with 3 trials, at least one of the later two is pruned unless it is
           # better than the first -- so make it certain with a threshold no loss can meet
           "~hydra.sweeper.pruner.n_startup_trials", "~hydra.sweeper.pruner.n_warmup_steps",
           "hydra.sweeper.pruner._target_=optuna.pruners.ThresholdPruner",
           "+hydra.sweeper.pruner.upper=1.0e-9", "+hydra.sweeper.pruner.n_warmup_steps=1"]
    done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=900,
                          env={**os.environ, "PYTHONWARNINGS": "ignore", "OMP_NUM_THREADS": "1"})
    assert done.returncode == 0, done.stderr[-3000:]
    study = optuna.load_study(study_name="qrnn_qrnn_tiny", storage=url)
    assert [t.state for t in study.trials] == [TrialState.PRUNED] * 3
    for t in study.trials:  # epoch 0 is warm-up, so each trial is stopped after epoch 1
        assert sorted(t.intermediate_values) == [0, 1]
        assert all(v > 0 for v in t.intermediate_values.values())
