"""Superposition of force models (e.g. ``DMT(...) + Electrostatic(...)``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, final

import numpy as np

from . import _layout as L
from .base import AbstractForceModel
from .lennard_jones import LennardJones

__all__ = ["ForceSum"]


@final
class ForceSum(AbstractForceModel):
    """Sum of force models sharing one regime state.

    At most one member may carry a contact law; long-range and damping terms add.
    :class:`~simulator.forces.LennardJones` cannot be combined with a contact law: its ``z**-2``
    attraction shares the canonical ``VDW`` coefficient, which the compiled kernel freezes at
    ``-vdw / a0**2`` in contact (DMT continuity) or drops (hysteretic JKR), so the kernel would
    disagree with the NumPy reference inside contact.

    Parameters
    ----------
    terms : sequence of AbstractForceModel
        At least one model. Nested sums are flattened.
    """

    def __init__(self, terms: Sequence[AbstractForceModel]) -> None:
        flat: list[AbstractForceModel] = []
        for t in terms:
            if not isinstance(t, AbstractForceModel):
                raise ValueError(f"terms: expected force models, got {type(t).__name__}")
            flat.extend(t.terms if isinstance(t, ForceSum) else [t])
        if not flat:
            raise ValueError("terms: need at least one force model")
        self.terms = tuple(flat)
        c = self.coefficients()  # validates compatibility (one contact law, ...)
        if c[L.CONTACT] and any(isinstance(t, LennardJones) for t in flat):
            raise ValueError("terms: LennardJones cannot be combined with a contact law (its "
                             "z**-2 attraction would be frozen at a0 in contact)")

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
        z_held = np.where(contact, self.a0, z)  # long-range terms saturate at contact
        return sum((t._reference(z_held if t.saturates_in_contact else z, zdot, contact)
                    for t in self.terms), np.zeros_like(z))

    def parameters(self) -> dict[str, Any]:
        return {"terms": [t.to_dict() for t in self.terms]}
