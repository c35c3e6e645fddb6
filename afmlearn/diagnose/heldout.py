"""Held-out prediction: a model's steady orbit compared with data it was never fitted on.

Two designs (:class:`HeldOutDesign`):

* an experiment of **one** record: the last ``heldout_fraction`` of its periods are never
  fitted; the model fitted on the rest predicts them. Its drive phase is the recorded one
  when the file has it, otherwise the one nuisance aligned on the held-out span, as for a
  held-out set-point: the phase the fit projected out is the best one for the fit's
  whitened harmonics, not for the time-domain NRMSE, and at these error levels that
  difference decides (measured on an electrostatic draw at 1,000 samples/period: a phase
  0.25 mrad off the tail's own alignment raised the extension's NRMSE from 6.4e-5 to
  1.07e-4 and its gain from 0.40 to 0.03, while the two spans' measured phases agree to
  0.04 mrad);
* **several set-points**: whole set-points are held out (leave one out, or interleaved folds
  in gap order when there are many); the model is refitted without them and predicts their
  steady orbit at their rest gap. Their drive phase is the recorded one when the file has
  it (then the phase lag, and with it the dissipation, is predicted too); otherwise it is the
  one nuisance aligned on the held-out data, a single number against the whole orbit shape.

The steady orbit is what a simulation of the model predicts (shooting with 2,048 RK4 steps
per period, checked stable by its Floquet multipliers; otherwise a settle run from the
measured state): comparing from the measured initial state instead scores the decay of the
initial mismatch (measured: baseline NRMSE 1.9e-3 from the measured state vs 1.5e-4 on its
attractor, on a trace the baseline explains).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from .balance import harmonics
from .model import DiagnosisModel
from .output_error import OutputError, align_phase, settle_periods

__all__ = ["HeldOut", "steady_output", "sample_orbit", "phase_for"]

FloatArray = NDArray[np.float64]


@final
@dataclass
class HeldOut:
    """Held-out span of one observation: measured, denoised, each model's prediction.

    Attributes (all shape (n,) over the span)
    ----------
    tau : dimensionless times (from the record's first sample)
    measured : measured deflection / L_ref
    reference : the same denoised (Fourier series fitted to the span alone)
    reference_rate : its rate
    simulated, simulated_rate : per model key (``"none"`` the baseline, a cause name, or
        causes joined by ``+`` for a model extended step by step): the prediction
    phase : per model key, the drive phase used [rad]
    harmonics : complex amplitudes ``Y_n`` (n = 0..n_h) of ``reference``
        (``reference = Re sum_n Y_n e^{i n Omega tau}``), shape (n_h + 1,); None when not
        known (then a prediction needs its drive phase given)
    """

    tau: FloatArray
    measured: FloatArray
    reference: FloatArray
    reference_rate: FloatArray
    simulated: dict[str, FloatArray] = field(default_factory=dict)
    simulated_rate: dict[str, FloatArray] = field(default_factory=dict)
    phase: dict[str, float] = field(default_factory=dict)
    harmonics: NDArray[np.complex128] | None = None


def steady_output(oe: OutputError, i: int, model0: DiagnosisModel, *, max_settle: int
                  ) -> tuple[FloatArray, FloatArray]:
    """Measured output and true rate over one period (2,048 phases) of the phase-0 model's
    steady orbit at observation ``i``; NaN when the model has none."""
    mult: list[complex] = []
    x, v, ok = oe.orbit(i, model0, n_out=2048, multipliers=mult)
    if not ok or not mult or max(abs(m) for m in mult) >= 1.0:
        s0, a0 = oe.start(i, model0)
        n = 2048
        period = 2 * math.pi / model0.omega
        x, v = model0.simulate(s0, attached0=a0, tau0=0.0, dtau=period / n, n_samples=n,
                               substeps=1,
                               settle_periods=settle_periods(model0, cap=max_settle))
    return model0.measured(x), v


def phase_for(y0: FloatArray, Y: NDArray[np.complex128], recorded: float | None) -> float:
    """Drive phase of a held-out prediction: the recorded one, else the one aligning the
    phase-0 orbit ``y0`` (one period on a uniform grid) with the held-out harmonics ``Y``
    (``u = Re sum Y_n e^{i n Omega tau}``)."""
    if recorded is not None:
        return float(recorded)
    X0 = harmonics(y0, Y.size - 1)
    return align_phase(X0, Y, 1.0)


def sample_orbit(u: FloatArray, omega: float, tau: FloatArray, phase: float) -> FloatArray:
    """Values at ``tau`` of the orbit with drive phase ``phase`` whose phase-0 period is
    ``u`` (uniform grid): ``u(Omega tau - phase)``, periodic cubic spline."""
    grid = np.linspace(0.0, 2 * np.pi, u.size + 1)
    spline = CubicSpline(grid, np.append(u, u[0]), bc_type="periodic")
    return spline(np.mod(omega * tau - phase, 2 * np.pi))
