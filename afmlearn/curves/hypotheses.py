"""Candidate tip--sample laws for lock-in curves: the baseline and one extension per cause.

A hypothesis is a cause name and the parameters it frees on top of the baseline (VdW--DMT
sphere: attraction ``vdw`` and contact ``stiffness`` free, exponent 1.5, no dissipation). The
same causes as ``design.md`` §3 where curves can show them, plus ``drift`` (the sample moving
against the piezo during the ramp), which only curves show.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

__all__ = ["Parameter", "Hypothesis", "BASELINE", "EXTENSIONS", "DRIFT", "FAR_OFF"]

#: pseudo-field of the drift rate of the rest gap (not a law term)
DRIFT = "drift"
#: start of the far-field damping coefficient that leaves it practically off (a thousandth of
#: a typical lever's own damping 1/Q ~ 5e-3)
FAR_OFF = 1e-7


@final
@dataclass(frozen=True)
class Parameter:
    """One fitted parameter: a :class:`CurveLaw` field (or ``drift``), start and bounds.

    ``log`` parameters are fitted as ``log10`` of the value (bounds are values, > 0);
    ``alternatives`` are further starting values tried (the best start by cost is kept).
    """

    field: str
    init: float
    low: float
    high: float
    log: bool = True
    alternatives: tuple[float, ...] = ()


@final
@dataclass(frozen=True)
class Hypothesis:
    """A cause and the parameters it adds to the baseline."""

    cause: str
    parameters: tuple[Parameter, ...]


#: the baseline's free law parameters (starts are replaced by the fitter's scan)
BASELINE = Hypothesis("none", (Parameter("vdw", 1e-5, 1e-9, 1e-1),
                               Parameter("stiffness", 10.0, 1e-2, 1e5)))

EXTENSIONS: tuple[Hypothesis, ...] = (
    Hypothesis("contact_geometry", (Parameter("exponent", 2.0, 1.0, 3.5, log=False,
                                              alternatives=(1.2, 2.5)),)),
    Hypothesis("viscoelastic", (Parameter("visco", 0.05, 1e-5, 1e3,
                                          alternatives=(0.0005, 0.005, 0.5)),)),
    # two terms of one cause (physics.md: exponential damping): a near-contact loss (decay
    # up to 3 free amplitudes) and a far-field one (squeeze-film damping, decay 1 to 1000 free
    # amplitudes: microns), each off or on at the start; the Asylum curves show both (A, s4)
    Hypothesis("long_range_damping", (Parameter("damping", 1e-3, 1e-7, 1e1,
                                                alternatives=(1e-2,)),
                                      Parameter("decay_length", 0.1, 1e-3, 3.0,
                                                alternatives=(0.03, 0.5)),
                                      Parameter("far_damping", FAR_OFF, 1e-8, 1e-1,
                                                alternatives=(3e-4,)),
                                      Parameter("far_decay_length", 20.0, 1.0, 1000.0))),
    # the tail trades against the attraction: starts up to 100x the usual vdW scale, each
    # with the baseline's attraction rescaled (fit.RESCALES)
    Hypothesis("electrostatic", (Parameter("electrostatic", 1e-4, 1e-9, 1e0,
                                           alternatives=(1e-3, 1e-2)),)),
    Hypothesis("adhesion_hysteresis", (Parameter("neck", 0.01, 1e-5, 0.5,
                                                 alternatives=(0.003, 0.03)),)),
    # 1e-6 per unit time: ~0.05 free amplitudes over a 2000-period ramp
    Hypothesis(DRIFT, (Parameter(DRIFT, 0.0, -1e-4, 1e-4, log=False,
                                 alternatives=(-2e-6, 2e-6)),)),
)
