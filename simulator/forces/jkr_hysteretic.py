"""Hysteretic JKR contact: forms at ``delta = 0``, breaks at a negative ``delta_c`` (neck)."""

from __future__ import annotations

import math
from typing import Any, final

import numpy as np
from scipy.optimize import brentq

from .._scales import Scales
from .base import AbstractForceModel, check_range
from .law import ForceLaw, Kind, Term

__all__ = ["HystereticJKR"]


@final
class HystereticJKR(AbstractForceModel):
    """Johnson--Kendall--Roberts contact with a neck (history-dependent).

    In contact the force follows the JKR relations, parametrised by the contact radius ``a``:

    ``F = alpha a**3 - beta a**1.5``,  ``delta = a**2 / r_j - c_j sqrt(a)``

    (SI: ``alpha = 4 E* / (3 R)``, ``beta = sqrt(8 pi w E*)``, ``r_j = R``,
    ``c_j = sqrt(2 pi w / E*)``, ``w`` the work of adhesion). Contact forms when the tip
    reaches ``delta = 0`` on approach and breaks on retraction at the neck's stability limit
    ``delta_c = -(3/4) c_j s_m < 0`` with ``s_m = (c_j r_j / 4)**(1/3)``, where ``dF/d delta``
    diverges. Out of contact the force is the van der Waals tail ``-vdw / z**2``; by default
    ``vdw`` makes the force continuous where contact forms (``F(delta=0) = -(4/3) pi w R``), so
    the energy lost per cycle is the area between the neck and the tail.

    Parameters
    ----------
    a0 : float
        Contact onset, > 0.
    alpha, beta, r_j, c_j : float
        Dimensionless JKR constants (all > 0); see :meth:`from_si`.
    vdw : float, optional
        Tail coefficient; default: continuity at formation.
    """

    name = "jkr_hysteretic"

    def __init__(
        self,
        *,
        a0: float,
        alpha: float,
        beta: float,
        r_j: float,
        c_j: float,
        vdw: float | None = None,
    ) -> None:
        self._a0 = check_range("a0", a0, low=0.0, low_open=True)
        self.alpha = check_range("alpha", alpha, low=0.0, low_open=True)
        self.beta = check_range("beta", beta, low=0.0, low_open=True)
        self.r_j = check_range("r_j", r_j, low=0.0, low_open=True)
        self.c_j = check_range("c_j", c_j, low=0.0, low_open=True)
        if vdw is None:
            vdw = -self.contact_force(0.0) * self._a0**2
        self.vdw = check_range("vdw", vdw, low=0.0)

    @classmethod
    def from_si(
        cls,
        *,
        reduced_modulus_pa: float,
        tip_radius_m: float,
        work_of_adhesion_j_per_m2: float,
        a0_m: float,
        scales: Scales,
    ) -> HystereticJKR:
        """From E* [Pa], tip radius [m], work of adhesion ``w`` [J/m^2] and ``a0`` [m]."""
        e = check_range("reduced_modulus_pa", reduced_modulus_pa, low=0.0, low_open=True)
        r = check_range("tip_radius_m", tip_radius_m, low=0.0, low_open=True)
        w = check_range("work_of_adhesion_j_per_m2", work_of_adhesion_j_per_m2,
                        low=0.0, low_open=True)
        k, ell = scales.spring_constant, scales.length
        return cls(
            a0=check_range("a0_m", a0_m, low=0.0, low_open=True) / ell,
            alpha=4.0 * e * ell**2 / (3.0 * r * k),
            beta=math.sqrt(8.0 * math.pi * w * e * ell) / k,
            r_j=r / ell,
            c_j=math.sqrt(2.0 * math.pi * w / (e * ell)),
        )

    @property
    def neck_radius_sqrt(self) -> float:
        """``s_m = sqrt(a)`` at the neck's stability limit."""
        return (self.c_j * self.r_j / 4.0) ** (1.0 / 3.0)

    def contact_force(self, delta: float) -> float:
        """JKR force at indentation ``delta`` (scalar reference, via a bracketing root)."""
        s_m = self.neck_radius_sqrt
        if delta <= -0.75 * self.c_j * s_m:
            s = s_m
        else:
            def g(s: float) -> float:
                return s**4 / self.r_j - self.c_j * s - delta

            hi = s_m + 1.0
            while g(hi) < 0.0:
                hi *= 2.0
            s = brentq(g, s_m, hi, xtol=1e-15, rtol=1e-14)
        return self.alpha * s**6 - self.beta * s**3

    def law(self) -> ForceLaw:
        terms = (Term(Kind.JKR_CUBE, self.alpha, self.r_j, self.c_j),
                 Term(Kind.JKR_THREE_HALVES, -self.beta, self.r_j, self.c_j),
                 Term(Kind.DETACHED_POWER, -self.vdw, 2.0))
        return ForceLaw(terms, a0=self._a0, has_contact=True,
                        break_distance=0.75 * self.c_j * self.neck_radius_sqrt)

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        out = np.empty_like(z)
        for idx in np.ndindex(z.shape):
            if contact[idx]:
                out[idx] = self.contact_force(self._a0 - z[idx])
            else:
                out[idx] = -self.vdw / z[idx] ** 2
        return out

    def parameters(self) -> dict[str, Any]:
        return {"a0": self._a0, "alpha": self.alpha, "beta": self.beta, "r_j": self.r_j,
                "c_j": self.c_j, "vdw": self.vdw}
