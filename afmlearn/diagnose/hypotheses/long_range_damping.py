"""Cause ``long_range_damping``: distance-dependent dissipation out of contact."""

from __future__ import annotations

from collections.abc import Sequence
from typing import final

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter, energy_text, gain_text, length_parameter

__all__ = ["LongRangeDamping"]


@final
class LongRangeDamping(AbstractHypothesis):
    """Add ``c exp(-z/z_b) z'`` (squeeze film, capillary, hydration layer), z_b 1 - 20 nm."""

    cause = "long_range_damping"
    extension = "distance-decaying damping exp(-z/z_b) z'"
    explanation = ("energy is lost out of contact, by a damping that decays with the gap "
                   "(squeeze film, hydration or capillary layer)")

    def parameters(self, ctx: Context) -> list[Parameter]:
        return [length_parameter("decay_length", 1e-9, 20e-9, ctx, 8)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.replace(damping_decay=float(values[0]))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        zb = (model.spec.damping_decay or 0.0) * model.scales.length
        return (f"loss out of contact, decay length {zb * 1e9:.2f} nm; chi2 drop "
                f"{delta_chi2:.1f}, held-out gain {gain_text(gain)}"
                f"{energy_text(model, energy)}")
