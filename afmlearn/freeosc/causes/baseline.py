"""The baseline: a linear one-mode lever oscillating freely (a sinusoid, no harmonics)."""

from __future__ import annotations

from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["LinearLever"]


@final
class LinearLever(AbstractCause):
    """``y = c + A(t) cos(phi(t))``: no column beyond the offset."""

    name = "none"
    equation = "y = c + A cos(phi)"

    def _columns(self, demod: Demodulation) -> FloatArray:
        return np.empty((demod.phase.size, 0))
