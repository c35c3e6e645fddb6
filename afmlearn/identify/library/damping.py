"""Distance-dependent dissipation: ``exp(-z/z_b) z'`` and ``z^p z'^l`` (squeeze film etc.).

A dissipative force opposes the relative velocity: ``F_ts = -c exp(-z/z_b) z'`` with ``c > 0``
(physics.md section 1), so the identified coefficient of these terms is negative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np

from .base import AbstractTerm, FloatArray, Kind, TermInput, fmt

__all__ = ["ExponentialDamping", "GapRate"]


@final
@dataclass(frozen=True)
class ExponentialDamping(AbstractTerm):
    """``exp(-z/z_b) z'`` at every gap, decay length ``z_b > 0`` / L_ref."""

    decay_length: float
    kind = Kind.EXPONENTIAL_DAMPING

    def __post_init__(self) -> None:
        if not self.decay_length > 0:
            raise ValueError(f"decay_length must be > 0, got {self.decay_length!r}")

    @property
    def name(self) -> str:
        return f"exp(-z/{fmt(self.decay_length)}) z'"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.decay_length), 0.0)

    @property
    def uses_velocity(self) -> bool:
        return True

    @property
    def sign(self) -> int:
        return -1

    def evaluate(self, s: TermInput) -> FloatArray:
        return np.exp(-s.z / self.decay_length) * s.zdot

    def potential(self, s: TermInput) -> FloatArray | None:
        return -self.decay_length * np.exp(-s.z / self.decay_length)

    def latex(self) -> str:
        return rf"$e^{{-z/{fmt(self.decay_length)}}}\dot z$"


@final
@dataclass(frozen=True)
class GapRate(AbstractTerm):
    """``z^p z'^l [z > a0]`` out of contact (``l`` in {1, 2}; ``p = -1``: squeeze film)."""

    p: float
    l: int = 1  # noqa: E741
    kind = Kind.GAP_RATE

    def __post_init__(self) -> None:
        if not math.isfinite(self.p):
            raise ValueError(f"p must be finite, got {self.p!r}")
        if self.l not in (1, 2):
            raise ValueError(f"l must be 1 or 2, got {self.l!r}")

    @property
    def name(self) -> str:
        rate = "z'" if self.l == 1 else f"z'^{self.l}"
        return f"z^{fmt(self.p)} {rate} [z>a0]"

    @property
    def params(self) -> tuple[float, float]:
        return (float(self.p), float(self.l))

    @property
    def uses_velocity(self) -> bool:
        return True

    @property
    def sign(self) -> int:
        # z^p > 0 out of contact, so c z^p z' is dissipative for c <= 0
        return -1 if self.l == 1 else 0

    def evaluate(self, s: TermInput) -> FloatArray:
        out = np.zeros_like(s.z)
        m = s.z > s.a0
        out[m] = s.z[m] ** self.p * s.zdot[m] ** self.l
        return out

    def potential(self, s: TermInput) -> FloatArray | None:
        if self.l != 1:
            return None
        out = np.zeros_like(s.z)
        m = s.z > s.a0
        if self.p == -1.0:
            out[m] = np.log(s.z[m] / s.a0)
        else:
            q = self.p + 1.0
            out[m] = (s.z[m] ** q - s.a0 ** q) / q
        return out
