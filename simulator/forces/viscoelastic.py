"""DMT contact with a viscoelastic rate term (dissertation ch. 5, eq. 5.7)."""

from __future__ import annotations

from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range, clipped_pow
from .dmt import DMT, _dmt_reference, dmt_law
from .law import ForceLaw, Kind, Term

__all__ = ["ViscoelasticDMT"]


@final
class ViscoelasticDMT(AbstractForceModel):
    """DMT plus ``viscosity * delta**q * delta_dot`` in contact (``delta_dot = -z_dot``).

    The rate term is repulsive while indenting and attractive while retracting, and vanishes
    at ``delta = 0`` so the force stays continuous at ``a0``.

    Parameters
    ----------
    a0, vdw, stiffness, exponent :
        As in :class:`DMT`.
    viscosity : float
        ``c_v`` >= 0 (dimensionless: ``eta L**q omega0 / k`` for SI ``eta`` in N s / m**(1+q)).
    viscosity_exponent : float, default 0.5
        ``q`` in [0, 2] (0.5: sphere, Kelvin--Voigt contact).
    """

    name = "dmt_visco"

    def __init__(
        self,
        *,
        a0: float,
        vdw: float,
        stiffness: float,
        viscosity: float,
        exponent: float = 1.5,
        viscosity_exponent: float = 0.5,
    ) -> None:
        d = DMT(a0=a0, vdw=vdw, stiffness=stiffness, exponent=exponent)  # validates
        self._a0, self.vdw, self.stiffness, self.exponent = d.a0, d.vdw, d.stiffness, d.exponent
        self.viscosity = check_range("viscosity", viscosity, low=0.0)
        self.viscosity_exponent = check_range("viscosity_exponent", viscosity_exponent,
                                              low=0.0, high=2.0)

    @classmethod
    def from_si(
        cls,
        *,
        hamaker_j: float,
        tip_radius_m: float,
        reduced_modulus_pa: float,
        a0_m: float,
        viscosity_si: float,
        scales: Scales,
        exponent: float = 1.5,
        viscosity_exponent: float = 0.5,
    ) -> ViscoelasticDMT:
        """``viscosity_si`` in N s / m**(1 + q); other arguments as :meth:`DMT.from_si`."""
        d = DMT.from_si(hamaker_j=hamaker_j, tip_radius_m=tip_radius_m,
                        reduced_modulus_pa=reduced_modulus_pa, a0_m=a0_m, scales=scales,
                        exponent=exponent)
        eta = check_range("viscosity_si", viscosity_si, low=0.0)
        q = check_range("viscosity_exponent", viscosity_exponent, low=0.0, high=2.0)
        cv = eta * scales.length**q * scales.omega0 / scales.spring_constant
        return cls(**d.parameters(), viscosity=cv, viscosity_exponent=q)

    def law(self) -> ForceLaw:
        rate = Term(Kind.INDENTATION_RATE, self.viscosity, self.viscosity_exponent, 1.0)
        return dmt_law(a0=self._a0, vdw=self.vdw, stiffness=self.stiffness, p=self.exponent,
                       extra=(rate,))

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        rate = self.viscosity * clipped_pow(self._a0 - z, self.viscosity_exponent) * (-zdot)
        return _dmt_reference(self, z, contact) + np.where(contact, rate, 0.0)

    def parameters(self) -> dict[str, Any]:
        return {"a0": self._a0, "vdw": self.vdw, "stiffness": self.stiffness,
                "exponent": self.exponent, "viscosity": self.viscosity,
                "viscosity_exponent": self.viscosity_exponent}
