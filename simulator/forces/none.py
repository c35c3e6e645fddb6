"""No tip--sample interaction (free cantilever)."""

from __future__ import annotations

from typing import Any, final

import numpy as np

from .base import AbstractForceModel
from .law import ForceLaw

__all__ = ["NoInteraction"]


@final
class NoInteraction(AbstractForceModel):
    """``F = 0`` at every gap."""

    name = "none"

    def law(self) -> ForceLaw:
        return ForceLaw()

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return np.zeros_like(z)

    def parameters(self) -> dict[str, Any]:
        return {}
