"""Contact terms, active only for ``z <= a0``: bridging constant, ``delta^p``, ``delta^p delta'^l``.

``delta = a0 - z`` is the indentation and ``delta' = -z'`` its rate. ``delta^p`` with
``p = 1.5`` is the Hertz/DMT sphere, ``p = 2`` a cone; ``delta^p delta'`` with ``p = 0.5`` is
the viscoelastic (Kelvin--Voigt on a Hertz contact) term.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

import numpy as np

from .base import AbstractTerm, FloatArray, Kind, TermInput, fmt

__all__ = ["ContactIndicator", "Indentation", "IndentationRate"]


@final
@dataclass(frozen=True)
class ContactIndicator(AbstractTerm):
    """``[z <= a0]``: the bridging constant (adhesion force, long-range forces held at ``a0``)."""

    kind = Kind.CONTACT

    @property
    def name(self) -> str:
        return "[z<=a0]"

    @property
    def params(self) -> tuple[float, float]:
        return (0.0, 0.0)

    @property
    def contact_only(self) -> bool:
        return True

    @property
    def sign(self) -> int:
        # a force that switches on at contact is adhesion (JKR neck, meniscus, the long-range
        # force held at a0): attractive; a repulsive step would be an infinitely stiff onset
        return -1

    def evaluate(self, s: TermInput) -> FloatArray:
        return s.in_contact.astype(np.float64)

    def latex(self) -> str:
        return r"$[z\leq a_0]$"


@final
@dataclass(frozen=True)
class Indentation(AbstractTerm):
    """``delta^p [z <= a0]`` with ``p > 0`` (contact elasticity; exponent 1.5 sphere, 2 cone)."""

    p: float
    kind = Kind.INDENTATION

    def __post_init__(self) -> None:
        if not self.p > 0:
            raise ValueError(f"p must be > 0, got {self.p!r}")

    @property
    def name(self) -> str:
        return f"delta^{fmt(self.p)}"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.p), 0.0)

    @property
    def contact_only(self) -> bool:
        return True

    @property
    def sign(self) -> int:
        return 1

    def evaluate(self, s: TermInput) -> FloatArray:
        return s.indentation ** self.p

    def latex(self) -> str:
        return rf"$\delta^{{{fmt(self.p)}}}$"


@final
@dataclass(frozen=True)
class IndentationRate(AbstractTerm):
    """``delta^p delta'^l [z <= a0]``, ``p >= 0``, ``l`` in {1, 2} (contact dissipation).

    With ``l = 1`` the term is the total derivative of ``delta^(p+1)/(p+1)`` and has a potential.
    """

    p: float
    l: int = 1  # noqa: E741 - the exponent's name in the issue and physics.md
    kind = Kind.INDENTATION_RATE

    def __post_init__(self) -> None:
        if not self.p >= 0:
            raise ValueError(f"p must be >= 0, got {self.p!r}")
        if self.l not in (1, 2):
            raise ValueError(f"l must be 1 or 2, got {self.l!r}")

    @property
    def name(self) -> str:
        rate = "delta'" if self.l == 1 else f"delta'^{self.l}"
        return rate if self.p == 0 else f"delta^{fmt(self.p)} {rate}"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.p), float(self.l))

    @property
    def uses_velocity(self) -> bool:
        return True

    @property
    def contact_only(self) -> bool:
        return True

    @property
    def sign(self) -> int:
        return 1 if self.l == 1 else 0

    def evaluate(self, s: TermInput) -> FloatArray:
        d = s.indentation
        return np.where(s.in_contact, d ** self.p * (-s.zdot) ** self.l, 0.0)

    def potential(self, s: TermInput) -> FloatArray | None:
        if self.l != 1:
            return None
        return s.indentation ** (self.p + 1.0) / (self.p + 1.0)

    def latex(self) -> str:
        rate = r"\dot\delta" if self.l == 1 else rf"\dot\delta^{self.l}"
        return rf"${rate}$" if self.p == 0 else rf"$\delta^{{{fmt(self.p)}}}{rate}$"
