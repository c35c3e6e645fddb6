"""Calibration constraints on the lever's own coefficients: hard boxes plus Gaussian priors.

In the dimensionless equation ``x'' + D x' + K x = -F_ts + B cos(Omega tau - phi)`` the
calibration fixes ``K = 1`` (time in units of the calibrated ``1/omega0``), ``D = 1/Q`` and
``B = F_c`` (the drive measured on free data). Each is held in a box ``value * (1 +- tolerance)``
(the dissertation's +-15 %, physics.md section 5) **and** pulled towards the calibrated value by
a Gaussian prior whose width is the calibration's own uncertainty, entered as pseudo-rows
of the regression. The prior matters: in steady state ``x``, ``x'`` and the drive are nearly
collinear with the fundamental of the force, and within a +-15 % box the noise decides how the
fundamental is shared out (a 0.5 % error on ``K`` moves as much force as the whole adhesion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

__all__ = ["CalibrationConstraints"]

FloatArray = NDArray[np.float64]


def _frac(name: str, v: float | None, *, allow_none: bool = True) -> None:
    if v is None and allow_none:
        return
    if v is None or not (math.isfinite(v) and 0 <= v < 1):
        raise ValueError(f"{name} must be a fraction in [0, 1), got {v!r}")


@final
@dataclass(frozen=True)
class CalibrationConstraints:
    """Boxes and priors on ``K``, ``D`` and ``B``.

    Parameters
    ----------
    tolerance : float
        Default half-width of every box, relative (0.15 = +-15 %), in [0, 1).
    stiffness_tolerance, damping_tolerance, drive_tolerance : float or None
        Per-coefficient box half-widths (None: ``tolerance``).
    stiffness_uncertainty : float or None
        Relative standard deviation of the prior on ``K`` (``K = (f_true/f0)^2``: a resonance
        frequency known to 1e-3 gives 2e-3). None: no prior.
    damping_uncertainty : float or None
        Relative standard deviation of the prior on ``D = 1/Q`` (default 5 %). None: no prior.
    drive_uncertainty : float or None
        Relative standard deviation of the prior on ``B``; None: chosen from how ``F_c`` was
        obtained (1 % from a free trace, 3 % from a free amplitude, no prior without either).
    """

    tolerance: float = 0.15
    stiffness_tolerance: float | None = None
    damping_tolerance: float | None = None
    drive_tolerance: float | None = None
    stiffness_uncertainty: float | None = 2e-3
    damping_uncertainty: float | None = 0.05
    drive_uncertainty: float | None = None

    def __post_init__(self) -> None:
        _frac("tolerance", self.tolerance, allow_none=False)
        for name in ("stiffness_tolerance", "damping_tolerance", "drive_tolerance"):
            _frac(name, getattr(self, name))
        for name in ("stiffness_uncertainty", "damping_uncertainty", "drive_uncertainty"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0 or None, got {v!r}")

    def box(self, which: str) -> float:
        """Relative half-width of the box on ``which`` in {"stiffness", "damping", "drive"}."""
        v = getattr(self, f"{which}_tolerance")
        return self.tolerance if v is None else v

    def prior(self, which: str, drive_source: str = "none") -> float | None:
        """Relative prior width of ``which`` (None: no prior)."""
        if which == "drive" and self.drive_uncertainty is None:
            return {"free_deflection": 0.01, "free_amplitude": 0.03}.get(drive_source)
        return getattr(self, f"{which}_uncertainty")

    def lever_boxes(self, p: int, *, quality_factor: float, drive_amplitude: float | None,
                    drive_index: int = 2) -> tuple[FloatArray, FloatArray]:
        """Lower and upper bounds, shape (p,), boxing the lever's coefficients about the
        calibration: ``xi_0 = -D`` about ``-1/Q``, ``xi_1 = -K`` about -1 and, unless
        ``drive_amplitude`` is None, the in-phase drive ``xi_drive_index = B`` about ``F_c``;
        every other coefficient is unbounded."""
        lo, hi = np.full(p, -np.inf), np.full(p, np.inf)
        d0 = 1.0 / quality_factor
        tk, td, tb = self.box("stiffness"), self.box("damping"), self.box("drive")
        lo[0], hi[0] = -d0 * (1 + td), -d0 * (1 - td)
        lo[1], hi[1] = -(1 + tk), -(1 - tk)
        if drive_amplitude is not None:
            fc = drive_amplitude
            lo[drive_index], hi[drive_index] = fc * (1 - tb), fc * (1 + tb)
        return lo, hi

    def prior_gram(self, p: int, *, quality_factor: float, drive_amplitude: float | None,
                   drive_source: str, noise_variance: float,
                   drive_index: int = 2) -> tuple[FloatArray, FloatArray]:
        """The calibration priors as Gram additions ``sum_k w_k^2 (xi_k - mu_k)^2``.

        The lever's coefficients are ``xi_0 = -D`` (mean ``-1/Q``), ``xi_1 = -K`` (mean -1)
        and ``xi_drive_index = B`` (mean ``F_c``; no drive prior when ``drive_amplitude`` is
        None). A prior of relative width ``rel`` weighs ``w^2 = noise_variance /
        (rel |mu|)^2``, i.e. it counts as one row of that noise.

        Returns
        -------
        G0 : ndarray, shape (p, p)
            Diagonal additions to the Gram matrix.
        b0 : ndarray, shape (p,)
            Additions to the right-hand side.
        """
        G0, b0 = np.zeros((p, p)), np.zeros(p)
        pri: list[tuple[int, float, float | None]] = [
            (0, -1.0 / quality_factor, self.prior("damping")),
            (1, -1.0, self.prior("stiffness")),
        ]
        if drive_amplitude is not None:
            pri.append((drive_index, drive_amplitude, self.prior("drive", drive_source)))
        for k, mu, rel in pri:
            if rel is None:
                continue
            w2 = noise_variance / (rel * abs(mu)) ** 2
            G0[k, k] += w2
            b0[k] += w2 * mu
        return G0, b0
