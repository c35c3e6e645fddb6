"""Cause ``long_range_damping``: distance-dependent dissipation out of contact."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, final

from afmlearn.identify.library import ExponentialDamping
from simulator import Scales

from ..model import DiagnosisModel
from ..spec import AbstractForceTerm, ModelSpec
from .base import AbstractHypothesis, Context, Parameter, energy_text, gain_text, length_parameter

__all__ = ["LongRangeDamping", "DecayingDamping"]


@final
@dataclass(frozen=True)
class DecayingDamping(AbstractForceTerm):
    """``c exp(-z/z_b) z'`` (``c <= 0``), ``z_b = decay`` / L_ref."""

    decay: float
    key = "damping"

    def term(self) -> ExponentialDamping:
        return ExponentialDamping(decay_length=float(self.decay))

    def report(self, scales: Scales) -> dict[str, Any]:
        return {"damping_decay_m": self.decay * scales.length}


@final
class LongRangeDamping(AbstractHypothesis):
    """Add ``c exp(-z/z_b) z'`` (squeeze film, capillary, hydration layer), z_b 1 - 20 nm."""

    cause = "long_range_damping"
    extension = "distance-decaying damping exp(-z/z_b) z'"
    explanation = ("energy is lost out of contact, by a damping that decays with the gap "
                   "(squeeze film, hydration or capillary layer)")
    # on strong damping the equation error is no guide (measured, damping 8x the lever's: its
    # chi2 at the generating structure 518,298, at its chosen start 225,386): every decay length
    # of the grid is also placed on the current model's point and scored by output error, and
    # the best is refined next to the equation-error start (the output error before refinement
    # does not rank them either: on another strong draw the scan's start ended at 10,350, the
    # equation-error start at 4,013)
    output_error_scan = 8
    refine_both_starts = True
    # with a calibrated drive and recorded phases the starts come from the energy balance per
    # set-point instead (fit.energy_starts): the loss's spread over the set-points ranks the
    # decay lengths (on a constructed damping series, 5 nm: the two best 5.5 and 3.6 nm, where
    # every fit from the grid scan sat at the 1 nm bound), the best two are refined. Measured
    # there (4 x 20 periods): damping fit 764 -> 188, held-out gain 0.52 -> 0.90; on 5 further
    # noise seeds 611 -> 439, 814 -> 205; the visco-elastic series of the same seeds: one of
    # six then named damping (153 against visco 159; truth refit 138)
    energy_balance_start = True
    energy_scan = 2

    def parameters(self, ctx: Context) -> list[Parameter]:
        return [length_parameter("decay_length", 1e-9, 20e-9, ctx, 8)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.with_extension(DecayingDamping(decay=float(values[0])))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        term = model.spec.get(DecayingDamping)
        zb = (term.decay if term is not None else 0.0) * model.scales.length
        return (f"loss out of contact, decay length {zb * 1e9:.2f} nm; chi2 drop "
                f"{delta_chi2:.1f}, held-out gain {gain_text(gain)}"
                f"{energy_text(model, energy)}")
