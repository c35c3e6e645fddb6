"""JKR adhesion in the dissertation's (non-hysteretic) form (ch. 5, eq. 5.9)."""

from __future__ import annotations

import math
from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range
from .dmt import DMT, _dmt_reference, dmt_coefficients_from_si, dmt_law
from .law import ForceLaw

__all__ = ["JKR"]


@final
class JKR(AbstractForceModel):
    """DMT-shaped force whose adhesion is the JKR pull-off ``F_ad = 3 pi R gamma``.

    Conservative and single-valued (no neck): the dissertation's form. For the history-
    dependent neck see :class:`HystereticJKR`. Dimensionless parameters as :class:`DMT`.
    """

    name = "jkr"

    def __init__(self, *, a0: float, vdw: float, stiffness: float, exponent: float = 1.5) -> None:
        d = DMT(a0=a0, vdw=vdw, stiffness=stiffness, exponent=exponent)  # validates
        self._a0, self.vdw, self.stiffness, self.exponent = d.a0, d.vdw, d.stiffness, d.exponent

    @classmethod
    def from_si(
        cls,
        *,
        surface_energy_j_per_m2: float,
        tip_radius_m: float,
        reduced_modulus_pa: float,
        a0_m: float,
        scales: Scales,
        exponent: float = 1.5,
    ) -> JKR:
        """From the surface energy ``gamma`` [J/m^2], tip radius [m], E* [Pa], ``a0`` [m]."""
        g = check_range("surface_energy_j_per_m2", surface_energy_j_per_m2, low=0.0)
        fad = 3.0 * math.pi * tip_radius_m * g
        return cls(**dmt_coefficients_from_si(
            adhesion_force_n=fad, tip_radius_m=tip_radius_m,
            reduced_modulus_pa=reduced_modulus_pa, a0_m=a0_m, exponent=exponent,
            contact_coefficient=None, scales=scales))

    def law(self) -> ForceLaw:
        return dmt_law(a0=self._a0, vdw=self.vdw, stiffness=self.stiffness, p=self.exponent)

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return _dmt_reference(self, z, contact)

    def parameters(self) -> dict[str, Any]:
        return {"a0": self._a0, "vdw": self.vdw, "stiffness": self.stiffness,
                "exponent": self.exponent}
