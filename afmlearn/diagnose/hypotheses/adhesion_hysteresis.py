"""Cause ``adhesion_hysteresis``: a JKR neck breaks contact later than it forms."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, final

from simulator import Scales

from ..model import DiagnosisModel
from ..spec import AbstractNeck, ModelSpec
from .base import AbstractHypothesis, Context, Parameter, energy_text, gain_text, length_parameter

__all__ = ["AdhesionHysteresis", "Neck"]

#: relative half width of the tip-radius "parameter": held at the recording's tip radius
_HELD = 1e-6


@final
@dataclass(frozen=True)
class Neck(AbstractNeck):
    """A JKR neck that breaks ``length`` / L_ref past contact, on a tip of ``radius`` / L_ref.

    The JKR constants follow from the two lengths: ``r_j = radius`` and ``c_j`` such that the
    neck's stability limit ``0.75 c_j (c_j r_j / 4)**(1/3)`` is ``length``
    (:class:`~afmlearn.diagnose.spec.AbstractNeck`).
    """

    length: float
    radius: float = 1.0
    key = "neck"

    def __post_init__(self) -> None:
        if not (self.length > 0 and self.radius > 0):
            raise ValueError(f"Neck: length and radius must be > 0, got {self.length!r}, "
                             f"{self.radius!r}")

    def contact_constants(self) -> tuple[float, float]:
        r_j = float(self.radius)
        c_j = (float(self.length) / (0.75 * (r_j / 4.0) ** (1.0 / 3.0))) ** 0.75
        return r_j, c_j

    def report(self, scales: Scales) -> dict[str, Any]:
        return {"neck_length_m": self.length * scales.length,
                "neck_tip_radius_m": self.radius * scales.length}


def work_of_adhesion(model: DiagnosisModel) -> float:
    """The JKR work of adhesion ``w`` [J/m^2] of a fitted neck (0 without one).

    ``alpha = 4 E* L^2 / (3 R k)`` and ``c_j = sqrt(2 pi w / (E* L))`` give
    ``w = 3 alpha r_j c_j**2 k / (8 pi)`` (``k`` the spring constant, ``L`` = L_ref).
    """
    neck = model.spec.get(Neck)
    if neck is None:
        return 0.0
    alpha = float(model.force_coefficients[-1])
    r_j, c_j = neck.contact_constants()
    return 3.0 * alpha * r_j * c_j**2 * model.scales.spring_constant / (8.0 * math.pi)


@final
class AdhesionHysteresis(AbstractHypothesis):
    """History-dependent adhesion: the contact law becomes the hysteretic JKR contact.

    The attached branch (from contact on approach until the neck's stability limit on
    retraction) follows the JKR force of the simulator's
    :class:`simulator.forces.HystereticJKR`: a pull already where contact forms, growing to the
    pull-off force and snapping at ``z = a0 + d_c``; the JKR stiffness ``alpha`` is the one
    linear coefficient (:class:`~afmlearn.diagnose.spec.AbstractNeck`). ``d_c`` is searched
    from 0.1 to 3 nm; the tip radius is the recording's (``Context.tip_radius``: from the
    file, else 10 nm), held (a zero-width parameter, so that :meth:`extend` sees it).
    """

    cause = "adhesion_hysteresis"
    extension = "JKR neck (history-dependent adhesion)"
    explanation = ("contact breaks later on retraction than it forms (a JKR neck): "
                   "rate-independent loss at pull-off")
    # the snap is a jump of the force, which the linearised harmonic balance cannot rank:
    # every neck length of the grid goes to the output-error stage (one orbit), and on joint
    # fits every neck length is scored by output error on the current model's point, the
    # equation-error start and the scan's best both refined (measured on a seed-2026 neck
    # series: drop 209.4 -> 217.5, the drawn law refitted with 40 evaluations 221.9)
    n_starts = 12
    output_error_scan = 12
    refine_both_starts = True
    #: output-error evaluations of each refinement at least (``fit.refine_output_error``;
    #: joint fits give 10): the snap at ``a0 + d_c`` makes the residual non-smooth in ``a0``
    #: and ``d_c``, and 10 evaluations stop short (measured on seed-2026 neck dev draw 0,
    #: 8 set-points, 200 samples/period, 1 %: chi2 387.6 at 10, 365.8 at 20; the drawn law
    #: refitted 372.7; the neck candidate's CPU unchanged within the load's noise)
    min_refine_nfev = 20

    def parameters(self, ctx: Context) -> list[Parameter]:
        r = float(ctx.tip_radius)
        return [length_parameter("neck_length", 0.1e-9, 3e-9, ctx, 12),
                Parameter("tip_radius", r * (1 - _HELD), r * (1 + _HELD), (r,), log=True)]

    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        """``values = (neck_length, tip_radius)`` (the radius may be left out: 1 L_ref)."""
        radius = float(values[1]) if len(values) > 1 else 1.0
        return spec.with_extension(Neck(length=float(values[0]), radius=radius))

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy=None) -> str:
        neck = model.spec.get(Neck)
        dc = (neck.length if neck is not None else 0.0) * model.scales.length
        return (f"loss at pull-off: JKR neck to {dc * 1e9:.2f} nm past contact (work of "
                f"adhesion {work_of_adhesion(model):.3g} J/m^2); chi2 drop {delta_chi2:.1f}, "
                f"held-out gain {gain_text(gain)}{energy_text(model, energy)}")
