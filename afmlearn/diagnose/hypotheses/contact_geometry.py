"""Cause ``contact_geometry``: the contact exponent is not the sphere's 1.5."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, final

import numpy as np

from ..model import DiagnosisModel
from ..spec import ModelSpec
from .base import AbstractHypothesis, Context, Parameter, Probe, gain_text

__all__ = ["ContactGeometry"]


@final
class ContactGeometry(AbstractHypothesis):
    """Free contact exponent ``p`` of ``delta^p`` in [1, 3.5] (cone: 2; polymers: ~2.3)."""

    cause = "contact_geometry"
    extension = "free contact exponent delta^p"
    explanation = ("the force grows with indentation with an exponent other than the "
                   "sphere's 1.5 (cone-like tip)")

    def parameters(self, ctx: Context) -> list[Parameter]:
        return [Parameter("contact_exponent", 1.0, 3.5, (1.0, 1.25, 1.75, 2.0, 2.25, 2.5, 3.0),
                          nested=1.5)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        return spec.replace(contact_exponent=float(values[0]))

    #: exponents of the profile likelihood (the searched range, step 0.125)
    profile_grid = tuple(float(v) for v in np.round(np.arange(1.0, 3.5001, 0.125), 3))
    #: chi-square rise that bounds a 95 % interval of one parameter
    level = 3.841

    def details(self, model: DiagnosisModel, probe: Probe) -> dict[str, Any]:
        """95 % profile-likelihood interval of the exponent (``a0``, the drive phases and
        every coefficient refitted at each exponent, all observations at once).

        Across set-points the indentation depth changes while the law stays, which is what
        separates the exponent from ``a0`` and the stiffness; on one orbit the profile is
        flat. The interval is where the profile chi-square is within 3.84 of its minimum; an
        end that reaches the searched range [1, 3.5] means the data do not bound it.
        """
        grid = np.asarray(self.profile_grid)
        chi = probe.profile("contact_exponent", grid)
        best = int(np.argmin(chi))
        rise = chi - chi[best] - self.level
        lo, hi = float(grid[0]), float(grid[-1])
        bounded_lo = bounded_hi = False
        for j in range(best, 0, -1):
            if rise[j - 1] > 0:
                lo = float(np.interp(0.0, [rise[j], rise[j - 1]], [grid[j], grid[j - 1]]))
                bounded_lo = True
                break
        for j in range(best, grid.size - 1):
            if rise[j + 1] > 0:
                hi = float(np.interp(0.0, [rise[j], rise[j + 1]], [grid[j], grid[j + 1]]))
                bounded_hi = True
                break
        bounded = bounded_lo and bounded_hi
        p = float(model.spec.contact_exponent)
        text = (f"95 % profile interval of the exponent [{lo:.2f}, {hi:.2f}]" if bounded else
                f"the data do not bound the exponent (95 % profile interval [{lo:.2f}, "
                f"{hi:.2f}] reaches the searched range)")
        return {"exponent": p, "exponent_interval": [lo, hi], "bounded": bounded,
                "profile": {"exponent": grid.tolist(), "chi2": chi.tolist()},
                "profile_minimum": float(grid[best]) if math.isfinite(chi[best]) else None,
                "text": text}

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        return (f"force-indentation exponent {model.spec.contact_exponent:.2f} instead of "
                f"1.5; chi2 drop {delta_chi2:.1f}, held-out gain {gain_text(gain)}")
