"""Cause ``higher_mode``: a second flexural eigenmode takes part (e.g. 6:1 internal resonance)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, final

import numpy as np

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter, Probe, gain_text

__all__ = ["HigherMode"]


@final
class HigherMode(AbstractHypothesis):
    """Add mode 2 (frequency ratio, Q2, tip-force gain g2) sharing the tip force and drive.

    The ratio is searched on ``[4.5, 8]`` (rectangular beam: 6.267) unless the file gives the
    measured ``f2``; then within +-3 % of it.

    Parameters
    ----------
    qrnn : bool
        Also score every record with the shipped QRNN mode-coupling checkpoint (issue 4) and
        report it as independent evidence; it does not change the decision (its training
        data are base-excited NCLR-like sweeps: measured score 2e-4 on a tip-excited 6:1
        case the fit names with gain 0.76). Any failure (no torch, no checkpoint, a record
        outside its range) raises.
    """

    def __init__(self, *, qrnn: bool = False) -> None:
        self.qrnn = qrnn

    cause = "higher_mode"
    extension = "second eigenmode"
    explanation = "a higher flexural eigenmode takes part in the motion"

    def parameters(self, ctx: Context) -> list[Parameter]:
        if ctx.higher_mode_ratios:
            r = float(ctx.higher_mode_ratios[0])
            ratio = Parameter("frequency_ratio", 0.97 * r, 1.03 * r,
                              tuple(np.linspace(0.97 * r, 1.03 * r, 13)))
        else:
            ratio = Parameter("frequency_ratio", 4.5, 8.0, tuple(np.linspace(4.5, 8.0, 71)))
        return [ratio,
                Parameter("quality_factor_2", 30.0, 5000.0, (300.0, 1500.0), log=True),
                Parameter("force_gain", 1e-4, 10.0, (0.01, 1.0), log=True, nested=1e-4)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        r, q2, g2 = (float(v) for v in values)
        return spec.replace(mode2=(r, q2, g2))

    def details(self, model: DiagnosisModel, probe: Probe) -> dict[str, Any]:
        """The QRNN coupling score of every record (when ``qrnn``)."""
        if not self.qrnn:
            return {}
        from afmlearn.qrnn.infer import load_module, predict_trace
        module, run, used = load_module(None)
        rows = [predict_trace(t, module, run)["summary"]["traces"][0] for t in probe.traces]
        score = max(float(r["score"]) for r in rows)
        flag = any(bool(r["flag"]) for r in rows)
        return {"qrnn_coupling": {"score": score, "flag": flag,
                                  "scores": [float(r["score"]) for r in rows],
                                  "checkpoint": Path(used).name},
                "text": f"QRNN coupling score {score:.2f} "
                        f"({'coupled' if flag else 'not coupled'})"}

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        r, q2, g2 = model.spec.mode2 or (np.nan, np.nan, np.nan)
        n = r / model.omega
        return (f"second mode at f2/f0 = {r:.3f} (Q2 = {q2:.0f}, gain {g2:.2f}) next to "
                f"harmonic {n:.2f} of the drive; chi2 drop {delta_chi2:.1f}, held-out gain "
                f"{gain_text(gain)}")
