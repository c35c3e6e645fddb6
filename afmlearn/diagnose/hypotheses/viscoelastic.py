"""Cause ``viscoelastic``: rate-dependent dissipation while indenting."""

from __future__ import annotations

from collections.abc import Sequence
from typing import final

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter, energy_text, gain_text

__all__ = ["Viscoelastic"]


@final
class Viscoelastic(AbstractHypothesis):
    """Add ``c sqrt(delta) delta'`` in contact (one linear coefficient, c >= 0).

    A Kelvin--Voigt solid under a sphere: the contact radius grows as ``sqrt(R delta)``, so the
    viscous force is ``~ eta sqrt(R delta) delta'`` (dissertation ch. 5 eq. 5.7). The exponent
    is fixed, not searched: a free exponent runs to 0 on noisy orbits, i.e. to a force that
    jumps at contact onset, whose periodic orbit neither the linearised noise model nor
    shooting handles, and it buys nothing the data can resolve (measured: chi2 changes by less
    than 1 between exponents 0.3 and 0.7 on the benchmark traces).
    """

    cause = "viscoelastic"
    extension = "visco-elastic contact term sqrt(delta) delta'"
    explanation = ("the sample dissipates energy while indented, at a rate set by the "
                   "indentation speed (visco-elastic contact)")
    exponent = 0.5

    def parameters(self, ctx: Context) -> list[Parameter]:
        return []

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.replace(visco_exponent=self.exponent)

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        return (f"loss only while indenting, delta^{model.spec.visco_exponent:.2f} delta' term; "
                f"chi2 drop {delta_chi2:.1f}, held-out gain {gain_text(gain)}"
                f"{energy_text(model, energy)}")
