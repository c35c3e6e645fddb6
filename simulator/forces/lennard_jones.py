"""Lennard-Jones sphere--plane interaction (dissertation ch. 2, eq. 2.1)."""

from __future__ import annotations

from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range
from .law import ForceLaw, Kind, Term

__all__ = ["LennardJones"]


@final
class LennardJones(AbstractForceModel):
    """``F = repulsion / z**8 - attraction / z**2`` (smooth, no contact branch).

    Parameters
    ----------
    repulsion : float
        Coefficient of the ``z**-8`` term, >= 0 (dimensionless, ``A1 R / (180 k L**9)``).
    attraction : float
        Coefficient of the ``z**-2`` term, >= 0 (dimensionless, ``A2 R / (6 k L**3)``).
    """

    name = "lj"
    combines_with_contact = False

    def __init__(self, *, repulsion: float, attraction: float) -> None:
        self.repulsion = check_range("repulsion", repulsion, low=0.0)
        self.attraction = check_range("attraction", attraction, low=0.0)

    @classmethod
    def from_si(
        cls, *, a1_jm6: float, a2_j: float, tip_radius_m: float, scales: Scales
    ) -> LennardJones:
        """From the Hamaker-type constants ``A1`` [J m^6], ``A2`` [J] and tip radius [m]."""
        a1 = check_range("a1_jm6", a1_jm6, low=0.0)
        a2 = check_range("a2_j", a2_j, low=0.0)
        r = check_range("tip_radius_m", tip_radius_m, low=0.0, low_open=True)
        k, ell = scales.spring_constant, scales.length
        return cls(repulsion=a1 * r / (180.0 * k * ell**9), attraction=a2 * r / (6.0 * k * ell**3))

    def law(self) -> ForceLaw:
        return ForceLaw((Term(Kind.INVERSE_POWER, self.repulsion, 8.0),
                         Term(Kind.INVERSE_POWER, -self.attraction, 2.0)))

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return self.repulsion / z**8 - self.attraction / z**2

    def parameters(self) -> dict[str, Any]:
        return {"repulsion": self.repulsion, "attraction": self.attraction}
