"""A higher flexural mode: a second oscillation at its own frequency, not a harmonic."""

from __future__ import annotations

import math
from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["HigherMode"]


@final
class HigherMode(AbstractCause):
    """Columns ``cos, sin(2 pi f_m t)`` (``coef_`` record units).

    Parameters
    ----------
    frequency_hz : float
        The mode's frequency [Hz], > 0 (e.g. the largest non-harmonic spectral peak).
    """

    name = "higher_mode"
    equation = "y = c + A cos(phi) + a cos(2 pi f_m t) + b sin(2 pi f_m t)"

    def __init__(self, *, frequency_hz: float) -> None:
        if not (math.isfinite(frequency_hz) and frequency_hz > 0):
            raise ValueError(f"frequency_hz must be > 0, got {frequency_hz!r}")
        self.frequency_hz = frequency_hz

    def _columns(self, demod: Demodulation) -> FloatArray:
        w = 2 * math.pi * self.frequency_hz * demod.time_s
        return np.column_stack([np.cos(w), np.sin(w)])
