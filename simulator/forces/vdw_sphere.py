"""Exact sphere--plane van der Waals force (Hamaker; dissertation ch. 6, eq. 6.7)."""

from __future__ import annotations

from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range
from .law import ForceLaw, Kind, Term

__all__ = ["SphereVdW"]


@final
class SphereVdW(AbstractForceModel):
    """``F = -s / (z**2 (z + 2 R)**2)`` with ``s = (2/3) H R**3`` (dimensionless).

    For ``z << R`` this tends to ``-H R / (6 z**2)``, the DMT tail. (``physics.md`` prints
    ``-H R**3 / (z**2 (2R + z)**2)`` without the factor 2/3; that form would not reduce to
    ``-H R / (6 z**2)``, so the exact Hamaker result is used here.)

    Combined with a contact law, the term is held at its value at ``a0`` while in contact,
    like the DMT tail.

    Parameters
    ----------
    strength : float
        ``s``, >= 0.
    radius : float
        Tip radius ``R`` in units of ``L_ref``, > 0.
    """

    name = "vdw_sphere"
    saturates_in_contact = True

    def __init__(self, *, strength: float, radius: float) -> None:
        self.strength = check_range("strength", strength, low=0.0)
        self.radius = check_range("radius", radius, low=0.0, low_open=True)

    @classmethod
    def from_si(cls, *, hamaker_j: float, tip_radius_m: float, scales: Scales) -> SphereVdW:
        """From the Hamaker constant [J] and tip radius [m]."""
        h = check_range("hamaker_j", hamaker_j, low=0.0)
        r = check_range("tip_radius_m", tip_radius_m, low=0.0, low_open=True) / scales.length
        return cls(strength=2.0 * h * r**3 / (3.0 * scales.spring_constant * scales.length**2),
                   radius=r)

    def law(self) -> ForceLaw:
        return ForceLaw((Term(Kind.SPHERE_VDW, -self.strength, self.radius),))

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return -self.strength / (z**2 * (z + 2.0 * self.radius) ** 2)

    def parameters(self) -> dict[str, Any]:
        return {"strength": self.strength, "radius": self.radius}
