"""Running the toy Hydra app (tests/hydra_plugins/app/toy.py) under the Optuna sweeper."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

TOY = Path(__file__).parent / "app" / "toy.py"


def toy_command(*overrides: str) -> list[str]:
    """The command of a toy sweep (``-m``) with ``overrides``."""
    return [sys.executable, str(TOY), "-m", *overrides]


def toy_env() -> dict[str, str]:
    return {**os.environ, "PYTHONWARNINGS": "ignore", "HYDRA_FULL_ERROR": "1",
            "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


@pytest.fixture
def run_toy(tmp_path: Path) -> Callable[..., subprocess.CompletedProcess[str]]:
    """``run_toy(*overrides)``: run a toy sweep in ``tmp_path`` to its end."""

    def run(*overrides: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
        return subprocess.run(toy_command(*overrides), cwd=tmp_path, env=toy_env(),
                              capture_output=True, text=True, timeout=timeout)

    return run


@pytest.fixture
def toy_cmd() -> Callable[..., list[str]]:
    """``toy_cmd(*overrides)``: the command line of a toy sweep, for Popen."""
    return toy_command
