"""Score (and, with a search, tune) the identifier on experiments matched to a recording.

Examples
--------
    python scripts/tune.py recording=outputs/demo/measured.h5
    python scripts/tune.py -m hparams_search=identifier_for_recording recording=rec.h5
    python scripts/tune.py -m hparams_search=identifier_for_recording recording=rec.h5 \
        hydra.sweeper.n_jobs=2 hydra.sweeper.n_trials=50

The search runs under the Optuna sweeper (hydra/sweeper: optuna) like every other entry point
and writes the best settings to outputs/tuned/experiment/identifier_for_<recording>.yaml. All
options live in conf/tune.yaml; the work is done by afmlearn.tune.matched.evaluate. Bad input
prints `error: ...` and exits with status 2.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig, OmegaConf

from afmlearn.tune.matched import evaluate

# ${stem:path}: a study named after the recording (conf/hparams_search/identifier_for_recording)
OmegaConf.register_new_resolver("stem", lambda path: Path(str(path)).stem, replace=True)


@hydra.main(config_path="../conf", config_name="tune", version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Run :func:`afmlearn.tune.matched.evaluate`; return the mean force accuracy."""
    with bad_input_exits(ValueError):
        metrics, _ = evaluate(cfg)
    for key, value in sorted(metrics.items()):
        print(f"{key:<20}  {value:.6g}")
    return metrics["force_accuracy"]


if __name__ == "__main__":
    main()
