"""Reference scales that connect the dimensionless simulator to SI units.

Conventions (``physics.md`` §1): time ``tau = omega0 * t``, lengths in units of the rest gap
``L_ref`` (the tip--sample gap with the cantilever undeflected), forces in units of
``k * L_ref``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

__all__ = ["Scales"]


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


@final
@dataclass(frozen=True)
class Scales:
    """SI scales of one cantilever set-up.

    Parameters
    ----------
    spring_constant : float
        Static spring constant ``k`` of the fundamental mode [N/m], > 0.
    resonance_frequency : float
        Free fundamental resonance ``f0`` [Hz], > 0.
    length : float
        Reference length ``L_ref`` [m], > 0: the rest gap.
    """

    spring_constant: float
    resonance_frequency: float
    length: float

    def __post_init__(self) -> None:
        _positive("spring_constant", self.spring_constant)
        _positive("resonance_frequency", self.resonance_frequency)
        _positive("length", self.length)

    @property
    def omega0(self) -> float:
        """Angular resonance frequency ``2 pi f0`` [rad/s]."""
        return 2.0 * math.pi * self.resonance_frequency

    @property
    def force(self) -> float:
        """Force unit ``k L_ref`` [N]."""
        return self.spring_constant * self.length

    @property
    def energy(self) -> float:
        """Energy unit ``k L_ref^2`` [J]."""
        return self.spring_constant * self.length**2

    @property
    def time(self) -> float:
        """Time unit ``1 / omega0`` [s]."""
        return 1.0 / self.omega0

    @property
    def velocity(self) -> float:
        """Velocity unit ``L_ref omega0`` [m/s]."""
        return self.length * self.omega0
