"""Simulated tapping traces shared by the preprocessing tests (real configs, small runs)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir

ROOT = Path(__file__).resolve().parents[3]

#: Q = 50 and 400 settling periods: the start transient has decayed to exp(-8 pi) ~ 1e-11, so
#: the recorded orbit is periodic to round-off (the default 2.5 Q periods leave ~4e-4)
SETTLED = ["cantilever.quality_factor=50", "scenario.settle_periods=400",
           "scenario.n_periods=20", "scenario.record_velocity=true", "progress=false",
           "free_trace_periods=5"]


def _simulate_tapping(path: Path, *overrides: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """Simulate a steady DMT tapping trace into ``path`` (config overrides appended)."""
    from afmlearn.simulate import simulate

    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=[f"output={path}", *SETTLED, *overrides])
    return simulate(cfg)


@pytest.fixture
def simulate_tapping():
    """``simulate_tapping(path, *overrides) -> (metrics, objects)``: a settled DMT trace."""
    return _simulate_tapping


@pytest.fixture(scope="session")
def noiseless_tapping(tmp_path_factory) -> tuple[Path, dict[str, Any]]:
    """(path, objects) of a noiseless steady DMT tapping trace, 200 samples per period."""
    path = tmp_path_factory.mktemp("tapping") / "clean.h5"
    _, obj = _simulate_tapping(path, "noise.level=0")
    return path, obj


@pytest.fixture(scope="session")
def noisy_tapping(tmp_path_factory) -> tuple[Path, dict[str, Any]]:
    """(path, objects) of the same trace with 1 % Gaussian detector noise."""
    path = tmp_path_factory.mktemp("tapping") / "noisy.h5"
    _, obj = _simulate_tapping(path, "noise.level=0.01")
    return path, obj
