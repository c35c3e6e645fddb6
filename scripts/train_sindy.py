"""Train (simulate, identify, score) the force identifier on a standard model (thin Hydra entry).

Examples
--------
    python scripts/train_sindy.py force=dmt noise.level=0.01
    python scripts/train_sindy.py force=dmt_visco scenarios.steady.samples_per_period=1500
    python scripts/train_sindy.py -m force=lj,dmt,dmt_visco,dmt_expdamp,jkr
    python scripts/train_sindy.py train.scenarios=[steady] identifier=fast

All options live in conf/ (see conf/train_sindy.yaml); the work is done by
afmlearn.identify.train.train. Bad settings print `error: ...` and exit with status 2.
"""

from __future__ import annotations

import math

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig

from afmlearn.identify.train import train
from afmlearn.plots.identify import training_figures


@hydra.main(config_path="../conf", config_name="train_sindy", version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Run :func:`afmlearn.identify.train.train`; return the mean whole-trace force accuracy."""
    with bad_input_exits(ValueError):  # InputError, TraceFormatError, bad settings
        metrics, objects = train(cfg, figures=training_figures)
    width = max(len(k) for k in metrics)
    for key, value in sorted(metrics.items()):
        print(f"{key:<{width}}  {value:.6g}")
    for name, run in objects["runs"].items():
        print(f"{name}: {run['record']['equation']}")
    print(f"run folder: {objects['output_dir']}")
    acc = [v for k, v in metrics.items() if k.endswith("force_accuracy_whole")]
    return float(sum(acc) / len(acc)) if acc and not any(map(math.isnan, acc)) else math.nan


if __name__ == "__main__":
    main()
