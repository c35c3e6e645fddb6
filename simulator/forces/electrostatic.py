"""Electrostatic sphere--plane attraction (dissertation ch. 6, eq. 6.2--6.5, sphere term)."""

from __future__ import annotations

import math
from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range
from .law import ForceLaw, Kind, Term

__all__ = ["Electrostatic"]

EPSILON_0 = 8.8541878128e-12  # F/m


@final
class Electrostatic(AbstractForceModel):
    """``F = -strength / (z (z + radius))`` (conservative, slower than ``1/z**2`` at large z).

    Combined with a contact law, the term is held at its value at ``a0`` while in contact (the
    capacitance gradient saturates once the tip touches), so it cannot diverge at ``z -> 0``.

    From ``F = -(1/2) dC/dz V**2`` with ``dC/dz = -2 pi eps0 R**2 / (z**2 + R z)``.

    Parameters
    ----------
    strength : float
        ``pi eps0 R**2 V**2 / (k L**3)`` in dimensionless form, >= 0.
    radius : float
        Tip radius in units of ``L_ref``, > 0.
    """

    name = "electrostatic"
    saturates_in_contact = True

    def __init__(self, *, strength: float, radius: float) -> None:
        self.strength = check_range("strength", strength, low=0.0)
        self.radius = check_range("radius", radius, low=0.0, low_open=True)

    @classmethod
    def from_si(
        cls, *, voltage_v: float, tip_radius_m: float, scales: Scales
    ) -> Electrostatic:
        """From the tip--sample potential difference [V] and tip radius [m]."""
        v = check_range("voltage_v", voltage_v, low=-1e4, high=1e4)
        r = check_range("tip_radius_m", tip_radius_m, low=0.0, low_open=True)
        ell = scales.length
        strength = math.pi * EPSILON_0 * r**2 * v**2 / (scales.spring_constant * ell**3)
        return cls(strength=strength, radius=r / ell)

    def law(self) -> ForceLaw:
        return ForceLaw((Term(Kind.SPHERE_ELECTROSTATIC, -self.strength, self.radius),))

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return -self.strength / (z * (z + self.radius))

    def parameters(self) -> dict[str, Any]:
        return {"strength": self.strength, "radius": self.radius}
