"""Several causes at once: the union of their columns (for the step-by-step naming)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["Combined"]


@final
class Combined(AbstractCause):
    """The baseline extended by every cause in ``parts`` (columns concatenated).

    Parameters
    ----------
    parts : sequence of AbstractCause
        At least one cause (their own fitted state is not used).
    """

    name = "combined"
    equation = "sum of the parts' columns"

    def __init__(self, parts: Sequence[AbstractCause]) -> None:
        if not parts or not all(isinstance(p, AbstractCause) for p in parts):
            raise ValueError("parts must be a non-empty sequence of causes")
        self.parts = tuple(parts)

    def _columns(self, demod: Demodulation) -> FloatArray:
        return np.column_stack([p._columns(demod) for p in self.parts])
