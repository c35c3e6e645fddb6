"""Constant and deflection-polynomial terms (static offsets, elastic nonlinearity)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

import numpy as np

from .base import AbstractTerm, FloatArray, Kind, TermInput

__all__ = ["Constant", "DeflectionPower"]


@final
@dataclass(frozen=True)
class Constant(AbstractTerm):
    """``1``: a constant force (static offset of the deflection)."""

    kind = Kind.CONSTANT

    @property
    def name(self) -> str:
        return "1"

    @property
    def params(self) -> tuple[float, float]:
        return (0.0, 0.0)

    def evaluate(self, s: TermInput) -> FloatArray:
        return np.ones_like(s.z)


@final
@dataclass(frozen=True)
class DeflectionPower(AbstractTerm):
    """``x^p`` for an integer ``p >= 2`` (``p = 1`` is the lever's own stiffness ``K``)."""

    power: int
    kind = Kind.DEFLECTION_POWER

    def __post_init__(self) -> None:
        if int(self.power) != self.power or self.power < 2:
            raise ValueError(f"power must be an integer >= 2, got {self.power!r}")

    @property
    def name(self) -> str:
        return f"x^{self.power}"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.power), 0.0)

    def evaluate(self, s: TermInput) -> FloatArray:
        return s.x ** int(self.power)
