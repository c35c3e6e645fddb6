"""Distance-decaying (exponential) damping (dissertation ch. 5, eq. 5.8, decaying form)."""

from __future__ import annotations

from typing import Any, final

import numpy as np

from .._scales import Scales
from .base import AbstractForceModel, check_range
from .law import ForceLaw, Kind, Term

__all__ = ["ExponentialDamping"]


@final
class ExponentialDamping(AbstractForceModel):
    """``F = -coefficient * exp(-z / decay_length) * z_dot`` at every gap.

    The dissertation prints ``exp(+z/z_beta)``, a damping that grows away from the sample;
    that is unphysical (squeeze-film and capillary losses decay with gap), so the decaying form
    is used. Combine with a contact law: ``DMT(...) + ExponentialDamping(...)``.

    Parameters
    ----------
    coefficient : float
        ``c_e`` >= 0 (dimensionless: ``c_SI omega0 / k`` for ``c_SI`` in N s / m).
    decay_length : float
        ``z_b`` > 0 in units of ``L_ref``.
    """

    name = "expdamp"

    def __init__(self, *, coefficient: float, decay_length: float) -> None:
        self.coefficient = check_range("coefficient", coefficient, low=0.0)
        self.decay_length = check_range("decay_length", decay_length, low=0.0, low_open=True)

    @classmethod
    def from_si(
        cls, *, coefficient_ns_per_m: float, decay_length_m: float, scales: Scales
    ) -> ExponentialDamping:
        """From a damping coefficient [N s/m] at ``z = 0`` and a decay length [m]."""
        c = check_range("coefficient_ns_per_m", coefficient_ns_per_m, low=0.0)
        zb = check_range("decay_length_m", decay_length_m, low=0.0, low_open=True)
        return cls(coefficient=c * scales.omega0 / scales.spring_constant,
                   decay_length=zb / scales.length)

    def law(self) -> ForceLaw:
        return ForceLaw((Term(Kind.EXPONENTIAL_DAMPING, -self.coefficient, self.decay_length),))

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        return -self.coefficient * np.exp(-z / self.decay_length) * zdot

    def parameters(self) -> dict[str, Any]:
        return {"coefficient": self.coefficient, "decay_length": self.decay_length}
