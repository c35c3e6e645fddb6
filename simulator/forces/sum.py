"""Superposition of force models (e.g. ``DMT(...) + Electrostatic(...)``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, final

import numpy as np

from .base import AbstractForceModel

__all__ = ["ForceSum"]


@final
class ForceSum(AbstractForceModel):
    """Sum of force models sharing one regime state.

    At most one member may carry a contact law; long-range and damping terms add.

    Parameters
    ----------
    terms : sequence of AbstractForceModel
        At least one model. Nested sums are flattened.
    """

    name = "sum"

    def __init__(self, terms: Sequence[AbstractForceModel]) -> None:
        flat: list[AbstractForceModel] = []
        for t in terms:
            if not isinstance(t, AbstractForceModel):
                raise ValueError(f"terms: expected force models, got {type(t).__name__}")
            flat.extend(t.terms if isinstance(t, ForceSum) else [t])
        if not flat:
            raise ValueError("terms: need at least one force model")
        self.terms = tuple(flat)
        self.coefficients()  # validates compatibility (one contact law, ...)

    @property
    def name(self) -> str:  # type: ignore[override]
        return "+".join(t.name for t in self.terms)

    @property
    def a0(self) -> float:
        return max(t.a0 for t in self.terms)

    @property
    def break_indentation(self) -> float:
        return min(t.break_indentation for t in self.terms)

    def _fill(self, c: np.ndarray) -> None:
        for t in self.terms:
            t._fill(c)

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return sum((t._reference(z, zdot, contact) for t in self.terms), np.zeros_like(z))

    def parameters(self) -> dict[str, Any]:
        return {"terms": [t.to_dict() for t in self.terms]}
