"""`AbstractHypothesis`: one physical cause, tested by fitting the model it extends.

A hypothesis names a cause of design.md section 3 and says how the baseline
:class:`~afmlearn.diagnose.spec.ModelSpec` is extended: which nonlinear parameters the
extension adds (:meth:`parameters`, with a search grid and bounds) and how their values enter
the spec (:meth:`extend`, the one hook every cause fills in: it adds the cause's extension
object, declared in the same file, with ``spec.with_extension(...)``). The diagnosis fits the
extension (grid, then joint refinement with ``a0`` and the drive phase), measures its gain on
held-out data and asks :meth:`evidence` for a one-line physical reading of the fit.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, final

import numpy as np
from numpy.typing import NDArray

from ..model import DiagnosisModel
from ..spec import ModelSpec

__all__ = ["AbstractHypothesis", "Parameter", "Context", "Probe", "energy_text",
           "gain_text", "length_parameter"]


@final
@dataclass(frozen=True)
class Parameter:
    """A nonlinear parameter of an extension: bounds, search grid, log scale or not.

    ``nested`` is the value at which the extension reduces to the baseline (None when a
    linear coefficient switches the extension off, so any value nests it).
    """

    name: str
    low: float
    high: float
    grid: tuple[float, ...]
    log: bool = False
    nested: float | None = None


@final
@dataclass(frozen=True)
class Context:
    """What the hypotheses may know about the recording (never its labels).

    Attributes
    ----------
    length_m : float
        ``L_ref`` [m] (the rest gap).
    amplitude : float
        First-harmonic amplitude of the orbit / L_ref.
    z_min, z_max : float
        Smallest and largest gap of the measured orbit / L_ref.
    tip_radius : float
        Tip radius / L_ref (from the file, else 10 nm).
    higher_mode_ratios : tuple of float
        Measured ``f_i / f0`` from the file (empty when unknown).
    free_detector : (float, float) or None
        ``(b2, b3)`` estimated from the harmonics of the free trace, when there is one.
    a0_max : float or None
        Largest contact onset ``a0`` / L_ref any fit may reach (None: only the factor box
        around the model extended, ``a0_factor``).
    """

    length_m: float
    amplitude: float
    z_min: float
    z_max: float
    tip_radius: float
    higher_mode_ratios: tuple[float, ...] = ()
    free_detector: tuple[float, float] | None = None
    a0_max: float | None = None


class Probe(Protocol):
    """What :meth:`AbstractHypothesis.details` may ask of a fitted extension."""

    #: the raw 1-D records of the experiment (labels never read)
    traces: Sequence[Any]

    def profile(self, name: str, values: Sequence[float]) -> NDArray[np.float64]:
        """Output-error chi-square (all observations) with the extension's parameter ``name``
        held at each of ``values`` and everything else refitted (warm-started in the order
        given)."""
        ...


class AbstractHypothesis(abc.ABC):
    """One cause and the model extension that represents it."""

    #: the cause's name in design.md section 3
    cause: ClassVar[str] = ""
    #: the extension in words (report)
    extension: ClassVar[str] = ""
    #: what the cause means physically, one sentence for the report's verdict
    explanation: ClassVar[str] = ""
    #: equation-error solutions handed to the output-error stage as starts
    n_starts: ClassVar[int] = 3
    #: how far ``a0`` may move from the model this extends (factor, > 1): a sphere baseline
    #: compensates a cone by a far-off ``a0`` (measured: base 0.0089 L_ref, true 0.0277)
    a0_factor: ClassVar[float] = 3.0
    #: factors of the current ``a0`` at which the extension's grid is also searched (several:
    #: joint fits add one start per factor with ``a0`` held there and rank the starts by output
    #: error; the sphere baseline absorbs a 4 V bias with ``a0`` 8x too large)
    a0_grid: ClassVar[tuple[float, ...]] = (1.0,)
    #: joint fits: how many of the grid's best points by equation error (one per value of the
    #: first parameter) are also scored by output error on the current model's point, the
    #: best becoming the start when it beats the equation-error start (``fit.scan_starts``;
    #: 0: none)
    output_error_scan: ClassVar[int] = 0
    #: with a scan: refine both the equation-error start and the scan's best, keep the better
    #: (False: only the one with the lower output error before refinement)
    refine_both_starts: ClassVar[bool] = False
    #: joint fits with a calibrated drive and recorded phases: the scan's starts come from the
    #: energy balance per set-point (``fit.energy_starts``), the grid scan when there are none
    energy_balance_start: ClassVar[bool] = False
    #: energy-balance starts: how many of the extension's grid points per onset (those whose
    #: one coefficient fits the set-points' energies best) are shot and refined
    energy_scan: ClassVar[int] = 1
    #: joint output-error refinements get at least this many evaluations (0: the diagnoser's
    #: ``joint_nfev``; read by ``fit.refine_output_error``; the JKR neck needs 20)
    min_refine_nfev: ClassVar[int] = 0

    @abc.abstractmethod
    def parameters(self, ctx: Context) -> list[Parameter]:
        """The extension's nonlinear parameters for this recording."""

    @abc.abstractmethod
    def extend(self, spec: ModelSpec, values: Sequence[float]) -> ModelSpec:
        """The baseline ``spec`` extended with parameter ``values`` (order of parameters)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def nested_values(self, params: Sequence[Parameter]) -> list[float]:
        """Parameter values at which the extension is the baseline."""
        return [p.grid[0] if p.nested is None else p.nested for p in params]

    def prior_log_odds(self, probe: Probe) -> float:
        """Log-odds for this cause from evidence outside the fit (e.g. a classifier on the
        records), added to the decision: the cause's null threshold on the chi-square drop is
        lowered by twice it (chi2 drop = 2 log likelihood ratio). Default 0 (none)."""
        return 0.0

    def details(self, model: DiagnosisModel, probe: Probe) -> dict[str, Any]:
        """Further evidence of the fitted extension for the report (JSON-able values), with
        an optional ``"text"`` appended to the evidence line. Default: nothing."""
        return {}

    def heldout_gain(self, held: Sequence[Any], *, before: str, after: str,
                     model: DiagnosisModel) -> float | None:
        """The extension's held-out gain on whole set-points held out, measured on its own
        signature, in place of the NRMSE gain ``1 - median NRMSE(after) / median
        NRMSE(before)``; None (the default) keeps the NRMSE gain.

        For a cause whose signature is far smaller than the error of a set-point's
        fundamental predicted at a gap never fitted (e.g. a second mode at one harmonic).
        ``held``: the diagnoser's :class:`~afmlearn.diagnose.heldout.HeldOut` per observation
        (``simulated[before]`` and ``simulated[after]`` where held out); ``model``: the
        extension at the representative observation.
        """
        return None

    def evidence(self, model: DiagnosisModel, *, delta_chi2: float, gain: float,
                 energy: NDArray[np.float64] | None = None) -> str:
        """One line: what the fitted extension says physically, and how strongly.

        ``energy``: energy into the sample per cycle [k L_ref^2] of (baseline, extension).
        """
        return (f"{self.extension}: chi2 drop {delta_chi2:.1f} (orbit-noise units), "
                f"held-out gain {gain_text(gain)}{energy_text(model, energy)}")


def length_parameter(name: str, low_m: float, high_m: float, ctx: Context, n: int, *,
                     extra: tuple[float, ...] = ()) -> Parameter:
    """A length searched on a log grid of ``n`` points from ``low_m`` to ``high_m`` [m]
    (in units of ``L_ref``), plus ``extra`` grid points (``L_ref`` units)."""
    lo, hi = low_m / ctx.length_m, high_m / ctx.length_m
    grid = sorted({*np.geomspace(lo, hi, n).tolist(), *extra})
    return Parameter(name, lo, hi, tuple(grid), log=True)


def gain_text(gain: float) -> str:
    """``+0.123``, or ``not computed`` (NaN: the decision did not need it)."""
    return "not computed" if gain != gain else f"{gain:+.3f}"


def energy_text(model: DiagnosisModel, energy: NDArray[np.float64] | None) -> str:
    """``"; sample takes X eV/cycle (baseline Y)"`` or empty."""
    if energy is None:
        return ""
    ev = model.scales.energy / 1.602176634e-19
    return f"; sample takes {energy[1] * ev:.3g} eV/cycle (baseline {energy[0] * ev:.3g})"
