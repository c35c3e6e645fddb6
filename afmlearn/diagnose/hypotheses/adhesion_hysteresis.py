"""Cause ``adhesion_hysteresis``: a JKR-like neck breaks contact later than it forms."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, final

from simulator import Scales

from ..model import DiagnosisModel
from ..spec import AbstractNeck, ModelSpec
from .base import AbstractHypothesis, Context, Parameter, energy_text, gain_text, length_parameter

__all__ = ["AdhesionHysteresis", "Neck"]


@final
@dataclass(frozen=True)
class Neck(AbstractNeck):
    """A JKR-like neck that breaks ``length`` / L_ref past contact on retraction."""

    length: float
    key = "neck"

    def neck_length(self) -> float:
        return float(self.length)

    def report(self, scales: Scales) -> dict[str, Any]:
        return {"neck_length_m": self.length * scales.length}


@final
class AdhesionHysteresis(AbstractHypothesis):
    """History-dependent adhesion: a neck that pulls from ``a0`` to ``a0 + d_c``.

    On retraction after contact the JKR neck holds the tip until ``z = a0 + d_c``; its pull
    over the van der Waals tail grows from zero where contact forms to its largest at the
    snap, modelled as ``n (z - a0)/d_c`` (``n <= 0``). ``d_c`` is searched from 0.1 to 3 nm.
    """

    cause = "adhesion_hysteresis"
    extension = "neck (history-dependent adhesion)"
    explanation = ("contact breaks later on retraction than it forms (a JKR-like neck): "
                   "rate-independent loss at pull-off")
    # the snap is a jump of the force, which the linearised harmonic balance cannot rank:
    # every neck length of the grid goes to the output-error stage
    n_starts = 12

    def parameters(self, ctx: Context) -> list[Parameter]:
        return [length_parameter("neck_length", 0.1e-9, 3e-9, ctx, 12)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.with_extension(Neck(length=float(values[0])))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        neck = model.spec.get(Neck)
        dc = (neck.length if neck is not None else 0.0) * model.scales.length
        return (f"loss at pull-off: neck to {dc * 1e9:.2f} nm past contact; chi2 drop "
                f"{delta_chi2:.1f}, held-out gain {gain_text(gain)}"
                f"{energy_text(model, energy)}")
