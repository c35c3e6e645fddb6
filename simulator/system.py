"""A driven cantilever with a tip--sample force: the thing the integrators advance."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, final

from .cantilever import Cantilever
from .excitation import AbstractExcitation
from .forces.base import AbstractForceModel

__all__ = ["System"]


@final
@dataclass(frozen=True)
class System:
    """Cantilever + tip--sample force + excitation (all dimensionless).

    Parameters
    ----------
    cantilever : Cantilever
    force : AbstractForceModel
    excitation : AbstractExcitation
    """

    cantilever: Cantilever
    force: AbstractForceModel
    excitation: AbstractExcitation

    def __post_init__(self) -> None:
        for name, cls in (("cantilever", Cantilever), ("force", AbstractForceModel),
                          ("excitation", AbstractExcitation)):
            if not isinstance(getattr(self, name), cls):
                raise ValueError(f"{name} must be a {cls.__name__}, got "
                                 f"{type(getattr(self, name)).__name__}")

    @property
    def n_modes(self) -> int:
        return self.cantilever.n_modes

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description (for labels)."""
        return {
            "cantilever": self.cantilever.to_dict(),
            "force": self.force.to_dict(),
            "excitation": {"kind": self.excitation.kind, "amplitude": self.excitation.amplitude},
        }
