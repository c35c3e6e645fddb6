"""Van der Waals--DMT contact with a free contact exponent (dissertation ch. 3 eq. 3.1, ch. 5)."""

from __future__ import annotations

from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range, clipped_pow
from .law import ForceLaw, Kind, Term

__all__ = ["DMT", "dmt_coefficients_from_si", "dmt_law"]


def dmt_coefficients_from_si(
    *,
    adhesion_force_n: float,
    tip_radius_m: float,
    reduced_modulus_pa: float,
    a0_m: float,
    exponent: float,
    contact_coefficient: float | None,
    scales: Scales,
) -> dict[str, float]:
    """Dimensionless ``a0``, ``vdw``, ``stiffness`` from SI quantities.

    The contact law is ``kappa * delta**p`` with the sphere-scaled prefactor
    ``kappa = (4/3) E* R**(2 - p)`` [N / m**p] unless ``contact_coefficient`` (SI, N / m**p) is
    given: ``F = (4/3) E* R**2 (delta / R)**p`` equals the Hertz force at ``delta = R`` for every
    ``p`` and is Hertz/DMT itself for ``p = 1.5``.
    The tail ``-c / z**2`` is tied to the adhesion force by continuity at ``a0``:
    ``c = F_ad a0**2``.
    """
    k, ell = scales.spring_constant, scales.length
    r = check_range("tip_radius_m", tip_radius_m, low=0.0, low_open=True)
    e = check_range("reduced_modulus_pa", reduced_modulus_pa, low=0.0, low_open=True)
    a0 = check_range("a0_m", a0_m, low=0.0, low_open=True)
    p = check_range("exponent", exponent, low=1.0, high=4.0)
    fad = check_range("adhesion_force_n", adhesion_force_n, low=0.0)
    kappa = (4.0 / 3.0) * e * r ** (2.0 - p) if contact_coefficient is None else float(
        check_range("contact_coefficient", contact_coefficient, low=0.0, low_open=True))
    return {
        "a0": a0 / ell,
        "vdw": fad * (a0 / ell) ** 2 / (k * ell),
        "stiffness": kappa * ell ** (p - 1.0) / k,
        "exponent": p,
    }


@final
class DMT(AbstractForceModel):
    """VdW--DMT force, positive = repulsive.

    ``z > a0``: ``F = -vdw / z**2``;  ``z <= a0``: ``F = -vdw / a0**2 + stiffness * delta**p``,
    ``delta = a0 - z``. Continuous at ``a0`` (``physics.md`` §3, ``C1 = -C3``).

    Parameters
    ----------
    a0 : float
        Contact onset (intermolecular distance) in units of ``L_ref``, > 0.
    vdw : float
        Attraction coefficient ``H R / (6 k L**3)``, >= 0; the adhesion force is ``vdw/a0**2``.
    stiffness : float
        Contact stiffness coefficient, > 0 (``(4/3) E* sqrt(R) L**0.5 / k`` for a sphere).
    exponent : float, default 1.5
        Contact exponent ``p`` in [1, 4] (1.5 sphere, 2 cone).
    """

    name = "dmt"

    def __init__(self, *, a0: float, vdw: float, stiffness: float, exponent: float = 1.5) -> None:
        self._a0 = check_range("a0", a0, low=0.0, low_open=True)
        self.vdw = check_range("vdw", vdw, low=0.0)
        self.stiffness = check_range("stiffness", stiffness, low=0.0, low_open=True)
        self.exponent = check_range("exponent", exponent, low=1.0, high=4.0)

    @classmethod
    def from_si(
        cls,
        *,
        hamaker_j: float,
        tip_radius_m: float,
        reduced_modulus_pa: float,
        a0_m: float,
        scales: Scales,
        exponent: float = 1.5,
        contact_coefficient: float | None = None,
    ) -> DMT:
        """From Hamaker constant [J], tip radius [m], reduced modulus E* [Pa] and ``a0`` [m]."""
        h = check_range("hamaker_j", hamaker_j, low=0.0)
        a0 = check_range("a0_m", a0_m, low=0.0, low_open=True)
        fad = h * tip_radius_m / (6.0 * a0**2)
        return cls(**dmt_coefficients_from_si(
            adhesion_force_n=fad, tip_radius_m=tip_radius_m,
            reduced_modulus_pa=reduced_modulus_pa, a0_m=a0_m, exponent=exponent,
            contact_coefficient=contact_coefficient, scales=scales))

    @property
    def adhesion(self) -> float:
        """Adhesion (pull-off) force ``vdw / a0**2`` (dimensionless)."""
        return self.vdw / self._a0**2

    def law(self) -> ForceLaw:
        return dmt_law(a0=self._a0, vdw=self.vdw, stiffness=self.stiffness, p=self.exponent)

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return _dmt_reference(self, z, contact)

    def parameters(self) -> dict[str, Any]:
        return {"a0": self._a0, "vdw": self.vdw, "stiffness": self.stiffness,
                "exponent": self.exponent}


def dmt_law(*, a0: float, vdw: float, stiffness: float, p: float,
            extra: tuple[Term, ...] = ()) -> ForceLaw:
    """``-vdw max(z, a0)**-2 + stiffness delta**p [z <= a0]`` (plus ``extra`` terms)."""
    terms = (Term(Kind.INVERSE_POWER, -vdw, 2.0), Term(Kind.INDENTATION, stiffness, p))
    return ForceLaw(terms + extra, a0=a0, has_contact=True)


def _dmt_reference(m: Any, z: np.ndarray, contact: np.ndarray) -> np.ndarray:
    """Plain DMT force for any object with ``a0, vdw, stiffness, exponent``."""
    a0 = m.a0
    inside = -m.vdw / a0**2 + m.stiffness * clipped_pow(a0 - z, m.exponent)
    with np.errstate(divide="ignore"):
        outside = -m.vdw / z**2
    return np.where(contact, inside, outside)
