"""Cause ``adhesion_hysteresis``: a JKR-like neck breaks contact later than it forms."""

from __future__ import annotations

from collections.abc import Sequence
from typing import final

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter, energy_text, gain_text, length_parameter

__all__ = ["AdhesionHysteresis"]


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
        return spec.replace(neck_length=float(values[0]))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        dc = (model.spec.neck_length or 0.0) * model.scales.length
        return (f"loss at pull-off: neck to {dc * 1e9:.2f} nm past contact; chi2 drop "
                f"{delta_chi2:.1f}, held-out gain {gain_text(gain)}"
                f"{energy_text(model, energy)}")
