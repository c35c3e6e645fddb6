"""Cause ``detector_nonlinearity``: the measurement chain distorts the deflection."""

from __future__ import annotations

from collections.abc import Sequence
from typing import final

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter, gain_text

__all__ = ["DetectorNonlinearity"]


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
        return spec.replace(detector=(float(values[0]), float(values[1])))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        b2, b3 = model.spec.detector or (0.0, 0.0)
        return (f"output map b2 = {b2:.3g}/L, b3 = {b3:.3g}/L^2 (harmonics not shaped by the "
                f"lever); chi2 drop {delta_chi2:.1f}, held-out gain {gain_text(gain)}")
