"""Long-range (out-of-contact) terms: ``z^-n`` and the sphere electrostatic ``1/(z (z+R))``.

Both are evaluated at ``max(z, a0)``: in contact they are held at their value at ``a0`` (the
DMT/JKR convention, physics.md section 3: the attraction is continuous at contact and becomes the
adhesion force). A discontinuous adhesion is the separate contact constant
(:class:`~afmlearn.identify.library.contact.ContactIndicator`). With ``a0`` below the smallest
gap of the trace they act unchanged at every sample (Lennard-Jones style).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

import numpy as np

from .base import AbstractTerm, FloatArray, Kind, TermInput, fmt

__all__ = ["InversePower", "SphereElectrostatic"]


@final
@dataclass(frozen=True)
class InversePower(AbstractTerm):
    """``max(z, a0)^-n`` (van der Waals ``n = 2``, Lennard-Jones wall ``n = 8``), ``n > 0``."""

    n: float
    kind = Kind.INVERSE_POWER

    def __post_init__(self) -> None:
        if not self.n > 0:
            raise ValueError(f"n must be > 0, got {self.n!r}")

    @property
    def name(self) -> str:
        return f"z^-{fmt(self.n)}"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.n), 0.0)

    @property
    def sign(self) -> int:
        # van der Waals-type powers attract (positive Hamaker constant), Pauli-type walls
        # (LJ z^-8) repel; a negative Hamaker constant (dissimilar media in a liquid) needs
        # ForceIdentifier(physical_signs=False)
        return -1 if self.n <= 6 else 1

    def evaluate(self, s: TermInput) -> FloatArray:
        return np.maximum(s.z, s.a0) ** (-self.n)

    def latex(self) -> str:
        return rf"$z^{{-{fmt(self.n)}}}$"


@final
@dataclass(frozen=True)
class SphereElectrostatic(AbstractTerm):
    """``1/(z (z + R))`` at ``max(z, a0)``: electrostatic sphere--plane shape, ``R > 0`` / L_ref."""

    radius: float
    kind = Kind.SPHERE_ELECTROSTATIC

    def __post_init__(self) -> None:
        if not self.radius > 0:
            raise ValueError(f"radius must be > 0, got {self.radius!r}")

    @property
    def name(self) -> str:
        return f"1/(z(z+{fmt(self.radius)}))"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.radius), 0.0)

    @property
    def sign(self) -> int:
        return -1

    def evaluate(self, s: TermInput) -> FloatArray:
        z = np.maximum(s.z, s.a0)
        return 1.0 / (z * (z + self.radius))

    def latex(self) -> str:
        return rf"$1/(z(z+{fmt(self.radius)}))$"
