"""Fixtures of the QRNN model / training / inference tests: tiny composed configs and one tiny
trained run shared by the session (a few seconds on the tiny data spec)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

ROOT = Path(__file__).resolve().parents[3]

#: overrides that make training tiny (data spec `qrnn_tiny`, 16 hidden units, 2 epochs)
TINY_TRAIN = [
    "data=qrnn_tiny",
    "data.horizon=2",
    "model.net.hidden_size=16",
    "trainer.max_epochs=2",
    "trainer.log_every_n_steps=1",
    "callbacks.progress_bar.refresh_rate=0",
    "threads=1",
]


@pytest.fixture(scope="session")
def qrnn_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One dataset cache folder for the whole session (the tiny set is generated once)."""
    return tmp_path_factory.mktemp("qrnn_cache")


@pytest.fixture(scope="session")
def compose_train(qrnn_cache_dir: Path) -> Callable[..., DictConfig]:
    """``compose_train(root, *overrides)``: conf/train_qrnn.yaml, tiny, writing under ``root``."""

    def make(root: Path, *overrides: str) -> DictConfig:
        with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
            return compose("train_qrnn", overrides=[
                *TINY_TRAIN, f"data.cache_dir={qrnn_cache_dir}", f"paths.root_dir={root}",
                *overrides])

    return make


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory: pytest.TempPathFactory,
             compose_train: Callable[..., DictConfig]) -> dict[str, Any]:
    """A tiny QRNN trained for 2 epochs: ``metrics``, ``objects`` and its ``checkpoint`` path."""
    from afmlearn.qrnn.train import train

    root = tmp_path_factory.mktemp("qrnn_run")
    cfg = compose_train(root, "run_name=tiny", f"export={root / 'tiny.ckpt'}")
    metrics, objects = train(cfg)
    return {"metrics": metrics, "objects": objects, "checkpoint": root / "tiny.ckpt",
            "cfg": cfg}
