"""Train the QRNN orbit / mode-coupling model (thin Hydra entry point).

Examples
--------
    python scripts/train_qrnn.py                                    # QRNN, default data, CPU
    python scripts/train_qrnn.py model=lstm trainer.max_epochs=20
    python scripts/train_qrnn.py model=qrnn data.modes=2 trainer.max_epochs=20
    python scripts/train_qrnn.py experiment=qrnn_default            # the shipped checkpoint
    python scripts/train_qrnn.py trainer=ddp trainer.devices=4      # several GPUs / processes

Re-running a command resumes from <output_dir>/checkpoints/last.ckpt (ckpt_path=last).
All options live in conf/ (see conf/train_qrnn.yaml); the work is done by
afmlearn.qrnn.train.train. Bad settings print one line `error: ...` and exit with status 2.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig

from afmlearn.qrnn.train import train


@hydra.main(config_path="../conf", config_name="train_qrnn", version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Run :func:`afmlearn.qrnn.train.train`; return ``val/loss`` (what a tuner minimises)."""
    with bad_input_exits(ValueError):  # bad settings name the key
        metrics, objects = train(cfg)
    width = max(len(k) for k in metrics)
    for key, value in sorted(metrics.items()):
        print(f"{key:<{width}}  {value:.6g}")
    print(f"run folder: {objects['output_dir']}")
    return float(metrics.get("val/loss", float("nan")))


if __name__ == "__main__":
    main()
