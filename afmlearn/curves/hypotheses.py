"""Candidate tip--sample laws for lock-in curves: the baseline and one extension per cause.

A hypothesis is a cause name and the parameters it frees on top of the baseline (VdW--DMT
sphere: attraction ``vdw`` and contact ``stiffness`` free, exponent 1.5, no dissipation). The
same causes as ``design.md`` §3 where curves can show them, plus ``drift`` (the sample moving
against the piezo during the ramp), which only curves show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import final

__all__ = ["Parameter", "Hypothesis", "BASELINE", "EXTENSIONS", "DRIFT", "FREE_SCALE",
           "FAR_OFF", "FAR_DECAY_M", "FAR_DECAY_LOW_M"]

#: pseudo-field of the drift rate of the rest gap (not a law term)
DRIFT = "drift"
#: pseudo-field of the free-amplitude scale: the amplitude far beyond the ramp (the drive's
#: steady state without the sample) / the curve's free amplitude (measured at the ramp's far
#: end, the length unit). 1 unless fitted; > 1 when a loss has not vanished at the ramp's start
FREE_SCALE = "free_scale"
#: start of the far-field damping coefficient that leaves it practically off (a thousandth of
#: a typical lever's own damping 1/Q ~ 5e-3)
FAR_OFF = 1e-7
#: start of the far-field damping's decay length [m]: a physical length (squeeze film, long-range
#: air damping), the same at every free amplitude of one lever
FAR_DECAY_M = 500e-9
#: lower bound of the far-field decay length [m] (50 nm in session 5 sent the strong synthetic
#: damping case of test_fit, a 40 nm decay, to a refuted fit beside the truth; session 6)
FAR_DECAY_LOW_M = 20e-9


@final
@dataclass(frozen=True)
class Parameter:
    """One fitted parameter: a :class:`CurveLaw` field (or ``drift``), start and bounds.

    ``log`` parameters are fitted as ``log10`` of the value (bounds are values, > 0);
    ``alternatives`` are further starting values tried (the best start by cost is kept).
    ``si_length``: ``init``, ``low``, ``high`` and ``alternatives`` are lengths in metres
    (a physical scale the free amplitude does not set, e.g. the far-field damping's decay);
    :meth:`in_units` turns them into the fit's unit. Else they are dimensionless.
    """

    field: str
    init: float
    low: float
    high: float
    log: bool = True
    alternatives: tuple[float, ...] = ()
    si_length: bool = False

    def in_units(self, length_m: float) -> Parameter:
        """The parameter in units of ``length_m`` [m] (the curve's free amplitude or a
        group's length unit): lengths in metres divided by it, others unchanged."""
        if not self.si_length:
            return self
        if not (math.isfinite(length_m) and length_m > 0.0):
            raise ValueError(f"length_m must be a finite length > 0 [m], got {length_m!r}")
        return replace(self, init=self.init / length_m, low=self.low / length_m,
                       high=self.high / length_m,
                       alternatives=tuple(a / length_m for a in self.alternatives),
                       si_length=False)


@final
@dataclass(frozen=True)
class Hypothesis:
    """A cause and the parameters it adds to the baseline.

    ``long_range``: the cause's force acts far from the surface (a joint fit rescans the
    surface positions under its law, :class:`afmlearn.curves.group.GroupFitter` ``rescan``).
    ``hysteretic``: the cause acts between approach and retraction (the adhesion neck forms
    on contact and breaks on the way out): a joint diagnosis tests it on the retraction of the
    fitted curves, not on left-out curves (:class:`afmlearn.curves.group_diagnose.GroupDiagnoser`).
    """

    cause: str
    parameters: tuple[Parameter, ...]
    hysteretic: bool = False
    long_range: bool = False

    def in_units(self, length_m: float) -> Hypothesis:
        """The hypothesis with every parameter in units of ``length_m`` [m]
        (:meth:`Parameter.in_units`)."""
        return replace(self, parameters=tuple(p.in_units(length_m) for p in self.parameters))


#: the baseline's free law parameters (starts are replaced by the fitter's scan)
BASELINE = Hypothesis("none", (Parameter("vdw", 1e-5, 1e-9, 1e-1),
                               Parameter("stiffness", 10.0, 1e-2, 1e5)))

EXTENSIONS: tuple[Hypothesis, ...] = (
    Hypothesis("contact_geometry", (Parameter("exponent", 2.0, 1.0, 3.5, log=False,
                                              alternatives=(1.2, 2.5)),)),
    Hypothesis("viscoelastic", (Parameter("visco", 0.05, 1e-5, 1e3,
                                          alternatives=(0.0005, 0.005, 0.5)),)),
    # two terms of one cause (physics.md: exponential damping): a near-contact loss (decay
    # up to 3 free amplitudes) and a far-field one (squeeze-film damping), each off or on at
    # the start; the Asylum curves show both (A, s4). The far decay is a physical length, not
    # a multiple of the free amplitude: it starts at FAR_DECAY_M (the Asylum lever's far law
    # decays over 440-500 nm at free amplitudes 22-55 nm; a start at 20 free amplitudes,
    # 1.6-3.4 um at 82-172 nm, left the term off there), bounds 20 nm to 20 um. The far
    # coefficient is in units of k / omega0, which the free amplitude does not scale either.
    # A far loss whose decay is longer than the ramp has not vanished at the ramp's start,
    # where the free amplitude (the length unit) is measured: the free-amplitude scale
    # (FREE_SCALE, the drive's free amplitude / that one) lets the fit see it (session 6: with
    # the scale held at 1 the loss had to vanish within the ~1.1 um Asylum ramp, and the
    # fitted decay, ~500 nm, was set by the ramp)
    Hypothesis("long_range_damping", (Parameter("damping", 1e-3, 1e-7, 1e1,
                                                alternatives=(1e-2,)),
                                      Parameter("decay_length", 0.1, 1e-3, 3.0,
                                                alternatives=(0.03, 0.5)),
                                      Parameter("far_damping", FAR_OFF, 1e-8, 1e-1,
                                                alternatives=(3e-4,)),
                                      Parameter("far_decay_length", FAR_DECAY_M,
                                                FAR_DECAY_LOW_M, 20e-6, si_length=True),
                                      Parameter(FREE_SCALE, 1.0, 0.9, 3.0, log=False)),
               long_range=True),
    # the tail trades against the attraction: starts up to 100x the usual vdW scale, each
    # with the baseline's attraction rescaled (fit.RESCALES)
    Hypothesis("electrostatic", (Parameter("electrostatic", 1e-4, 1e-9, 1e0,
                                           alternatives=(1e-3, 1e-2)),),
               long_range=True),
    Hypothesis("adhesion_hysteresis", (Parameter("neck", 0.01, 1e-5, 0.5,
                                                 alternatives=(0.003, 0.03)),),
               hysteretic=True),
    # 1e-6 per unit time: ~0.05 free amplitudes over a 2000-period ramp
    Hypothesis(DRIFT, (Parameter(DRIFT, 0.0, -1e-4, 1e-4, log=False,
                                 alternatives=(-2e-6, 2e-6)),)),
)
