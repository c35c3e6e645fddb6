"""Quantisation by the ADC: the record on a grid of step ``q``.

A sinusoid rounded to a grid gains harmonics of order ``q / A``. The column is the rounding
error of the baseline itself, ``round(x / q) q - x`` with ``x = A cos(phi)`` (coefficient 1
if quantisation made the waveform).
"""

from __future__ import annotations

import math
from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["Quantisation"]


@final
class Quantisation(AbstractCause):
    """Column ``round((x + o) / q) q - (x + o)``, dimensionless coefficient.

    Parameters
    ----------
    step : float
        Quantisation step ``q`` > 0, record units (the smallest difference of distinct values).
    grid_offset : float, default 0
        Offset ``o`` of the grid relative to the fundamental's zero, record units.
    """

    name = "quantisation"
    equation = "y = c + A cos(phi) + theta (Q_q(x) - x)"

    def __init__(self, *, step: float, grid_offset: float = 0.0) -> None:
        if not (math.isfinite(step) and step > 0):
            raise ValueError(f"step must be > 0, got {step!r}")
        self.step = step
        self.grid_offset = grid_offset

    def _columns(self, demod: Demodulation) -> FloatArray:
        x = demod.fundamental() + self.grid_offset
        return (np.round(x / self.step) * self.step - x)[:, None]
