"""Cause ``detector_nonlinearity``: the measurement chain distorts the deflection."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, final

from simulator import Scales

from ..model import DiagnosisModel
from ..spec import AbstractOutputMap, ModelSpec
from .base import AbstractHypothesis, Context, Parameter, gain_text

__all__ = ["DetectorNonlinearity", "DetectorMap"]


@final
@dataclass(frozen=True)
class DetectorMap(AbstractOutputMap):
    """``y = x + b2 x^2 + b3 x^3`` [b2: 1/L_ref, b3: 1/L_ref^2]."""

    b2: float
    b3: float
    key = "detector"

    def polynomial(self) -> tuple[float, float]:
        return (self.b2, self.b3)

    def report(self, scales: Scales) -> dict[str, Any]:
        L = scales.length
        return {"detector": {"b2_per_m": self.b2 / L, "b3_per_m2": self.b3 / L**2,
                             "b2": self.b2, "b3": self.b3}}


@final
class DetectorNonlinearity(AbstractHypothesis):
    """Instantaneous output map ``y = x + b2 x^2 + b3 x^3``.

    Started from the free trace's second and third harmonics when the file has one (a linear
    lever swinging freely is a pure sinusoid, so they measure the detector directly).
    """

    cause = "detector_nonlinearity"
    extension = "detector map y = x + b2 x^2 + b3 x^3"
    explanation = ("the detector, not the cantilever, distorts the signal (an output map "
                   "with quadratic and cubic terms)")

    def parameters(self, ctx: Context) -> list[Parameter]:
        a = max(ctx.amplitude, 1e-6)
        l2, l3 = 0.5 / a, 0.5 / a**2
        g2 = [0.0, -0.04 / a, 0.04 / a]
        g3 = [0.0]
        if ctx.free_detector is not None:
            g2 = [min(max(ctx.free_detector[0], -0.99 * l2), 0.99 * l2)] + g2
            g3 = [min(max(ctx.free_detector[1], -0.99 * l3), 0.99 * l3)] + g3
        return [Parameter("b2", -l2, l2, tuple(g2), nested=0.0),
                Parameter("b3", -l3, l3, tuple(g3), nested=0.0)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.with_extension(DetectorMap(b2=float(values[0]), b3=float(values[1])))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        det = model.spec.get(DetectorMap)
        b2, b3 = det.polynomial() if det is not None else (0.0, 0.0)
        return (f"output map b2 = {b2:.3g}/L, b3 = {b3:.3g}/L^2 (harmonics not shaped by the "
                f"lever); chi2 drop {delta_chi2:.1f}, held-out gain {gain_text(gain)}")
