"""Fixtures shared by the afmlearn tests: compose the real configs of conf/ with overrides."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import DictConfig

ROOT = Path(__file__).resolve().parents[2]

#: overrides that make each scenario tiny (settling shortened, few samples)
TINY = {
    "steady": ["scenario.n_periods=5", "scenario.settle_periods=10"],
    "transient": ["scenario.periods_before=2", "scenario.periods_after=5",
                  "scenario.settle_periods=10"],
    "approach": ["scenario.n_periods=20", "scenario.settle_periods=5",
                 "scenario.samples_per_period=50"],
    "sweep": ["scenario.n_points=3", "scenario.samples_per_point=300",
              "scenario.settle_periods=5"],
}


def _compose(overrides: list[str] | tuple[str, ...] = ()) -> DictConfig:
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        return compose("simulate", overrides=["progress=false", "free_trace_periods=3",
                                              *overrides])


@pytest.fixture
def compose_cfg() -> Callable[..., DictConfig]:
    """``compose_cfg(overrides)``: ``conf/simulate.yaml`` composed, progress bar off."""
    return _compose


@pytest.fixture
def tiny() -> dict[str, list[str]]:
    """Overrides that make each scenario tiny, keyed by scenario name."""
    return {k: list(v) for k, v in TINY.items()}


@pytest.fixture
def run_sim(tmp_path: Path) -> Callable[..., tuple[dict[str, Any], dict[str, Any]]]:
    """``run_sim(*overrides, name="trace.h5")``: simulate into ``tmp_path / name``."""
    from afmlearn.simulate import simulate

    def run(*overrides: str, name: str = "trace.h5"):
        return simulate(_compose([f"output={tmp_path / name}", *overrides]))

    return run


@pytest.fixture
def repo_root() -> Path:
    return ROOT
