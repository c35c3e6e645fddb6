"""Cause ``contact_geometry``: the contact exponent is not the sphere's 1.5."""

from __future__ import annotations

from collections.abc import Sequence
from typing import final

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter

__all__ = ["ContactGeometry"]


@final
class ContactGeometry(AbstractHypothesis):
    """Free contact exponent ``p`` of ``delta^p`` in [1, 3.5] (cone: 2; polymers: ~2.3)."""

    cause = "contact_geometry"
    extension = "free contact exponent delta^p"

    def parameters(self, ctx: Context) -> list[Parameter]:
        return [Parameter("contact_exponent", 1.0, 3.5, (1.0, 1.25, 1.75, 2.0, 2.25, 2.5, 3.0),
                          nested=1.5)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.replace(contact_exponent=float(values[0]))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        return (f"force-indentation exponent {model.spec.contact_exponent:.2f} instead of "
                f"1.5; chi2 drop {delta_chi2:.1f}, held-out gain {gain:+.3f}")
