"""Toy Hydra task for the sweeper tests: ``(x - 1)^2 + n`` (+0.5 for ``opt=b``) after a pause.

With ``marker_dir`` set, writes ``<marker_dir>/<pid>-<x>.start`` when a trial starts and
``.done`` when it ends, so a test can kill the process in the middle of a trial.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import hydra
from omegaconf import DictConfig

from afmlearn.tune import report


@hydra.main(config_path=".", config_name="toy", version_base="1.3")
def main(cfg: DictConfig) -> float:
    """The objective; reports it once as an intermediate value (step 0)."""
    tag = f"{os.getpid()}-{cfg.x:.12g}"
    folder = Path(cfg.marker_dir) if cfg.marker_dir else None
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{tag}.start").write_text("")
    time.sleep(float(cfg.sleep_s))
    value = (float(cfg.x) - 1.0) ** 2 + int(cfg.n) + (0.5 if cfg.opt == "b" else 0.0)
    report(value, step=0)
    if folder is not None:
        (folder / f"{tag}.done").write_text("")
    return value


if __name__ == "__main__":
    main()
