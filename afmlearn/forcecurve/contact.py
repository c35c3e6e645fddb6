"""`ContactFit`: a contact law fitted to one branch of a static force curve.

Model (force > 0 repulsive, separation ``d`` = piezo position minus deflection towards the
sample, i.e. the tip height up to an offset, larger = further from the sample):

    F(d) = 0                                   for d > d_c      (after the baseline)
    F(d) = a (d_c - d)^p - F_ad                for d <= d_c     (DMT-like contact)

``p = 3/2`` with ``a = (4/3) E* sqrt(R)`` is the DMT sphere (physics.md section 3); ``p`` free
is the contact exponent (cone-like tips: ~2). ``F_ad`` is the adhesion acting in contact. The
baseline (offset and slope of the non-contact part, e.g. virtual deflection) is removed
first with a straight line through the far ``baseline_fraction`` of the approach.

Fit: for each contact point on a grid (and each exponent on a grid when free), ``a`` and
``F_ad`` follow by linear least squares; the best pair is refined by a finer grid around it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io.instruments import ForceCurve

__all__ = ["Branch", "ContactFit", "branch"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True)
class Branch:
    """One segment of a force curve after the baseline.

    Attributes
    ----------
    separation_m : ndarray, shape (m,)
        Tip height up to an offset [m] (``z_piezo_m - deflection_m``), larger = further.
    force_n : ndarray, shape (m,)
        Force after the baseline [N], > 0 repulsive.
    """

    separation_m: FloatArray
    force_n: FloatArray


def branch(curve: ForceCurve, segment: int, *, baseline_fraction: float = 0.3) -> Branch:
    """The baseline-corrected ``segment`` (0 approach, 1 retraction) of ``curve``.

    The baseline is a straight line ``F = b0 + b1 z`` through the far ``baseline_fraction``
    of the APPROACH (largest piezo positions), subtracted from both segments.
    """
    if not 0 < baseline_fraction < 1:
        raise ValueError(f"baseline_fraction must be in (0, 1), got {baseline_fraction!r}")
    if segment not in (0, 1) or not np.any(curve.segment == segment):
        raise ValueError(f"segment must be 0 or 1 and present in the curve, got {segment!r}")
    z, f = curve.z_piezo_m, curve.force_n
    app = curve.segment == 0
    far = z[app] >= np.quantile(z[app], 1.0 - baseline_fraction)
    slope, offset = np.polyfit(z[app][far], f[app][far], 1)
    sel = curve.segment == segment
    force = f[sel] - (offset + slope * z[sel])
    # tip height: the piezo minus the deflection towards the sample (known only with k)
    sep = z[sel] - (curve.deflection_m[sel] - np.median(curve.deflection_m[app][far])
                    if curve.deflection_m is not None else 0.0)
    return Branch(np.asarray(sep, dtype=float), np.asarray(force, dtype=float))


@final
class ContactFit:
    """Least-squares contact law on one branch (scikit-learn style).

    Parameters
    ----------
    exponent : float or None
        Contact exponent p; None fits it on ``exponent_grid``. Default 1.5 (DMT sphere).
    exponent_grid : sequence of float
        Exponents tried when ``exponent`` is None.
    n_contact : int
        Contact points tried on the coarse grid (over the closest 70 % of the branch).

    Attributes
    ----------
    contact_point_m_, prefactor_, exponent_, adhesion_n_ : float
        ``d_c`` [m], ``a`` [N / m^p], ``p``, ``F_ad`` [N].
    rms_n_ : float
        Residual RMS on the fitted branch [N].
    """

    def __init__(self, *, exponent: float | None = 1.5,
                 exponent_grid: tuple[float, ...] = tuple(np.round(np.arange(1.0, 3.01, 0.05),
                                                                   2)),
                 n_contact: int = 80) -> None:
        self.exponent = exponent
        self.exponent_grid = exponent_grid
        self.n_contact = n_contact

    def fit(self, data: Branch) -> ContactFit:
        """Fit the branch; returns self."""
        if self.exponent is not None and not 0.5 <= self.exponent <= 5:
            raise ValueError(f"exponent must be in [0.5, 5] or None, got {self.exponent!r}")
        d, f = data.separation_m, data.force_n
        if d.size < 20:
            raise ValueError(f"a branch needs >= 20 points, got {d.size}")
        exponents = (self.exponent,) if self.exponent is not None else self.exponent_grid
        lo, hi = np.quantile(d, [0.0, 0.7])
        best = (np.inf, 0.0, 0.0, 0.0, 0.0)
        for grid in (np.linspace(lo, hi, self.n_contact), None):
            if grid is None:  # refine around the coarse optimum
                step = (hi - lo) / max(self.n_contact - 1, 1)
                grid = np.linspace(best[1] - step, best[1] + step, 41)
            for dc in grid:
                for p in exponents:
                    cost, a, fad = _linear(d, f, dc, p)
                    if cost < best[0]:
                        best = (cost, dc, p, a, fad)
        cost, self.contact_point_m_, self.exponent_, self.prefactor_, self.adhesion_n_ = best
        self.rms_n_ = float(np.sqrt(cost / d.size))
        return self

    def predict(self, separation_m: FloatArray) -> FloatArray:
        """Force [N] at ``separation_m`` (same offset as the fitted branch)."""
        delta = np.clip(self.contact_point_m_ - np.asarray(separation_m, dtype=float), 0, None)
        inside = delta > 0
        return np.where(inside, self.prefactor_ * delta**self.exponent_ - self.adhesion_n_, 0.0)


def _linear(d: FloatArray, f: FloatArray, dc: float, p: float) -> tuple[float, float, float]:
    """Least-squares ``a``, ``F_ad`` (a >= 0) for contact point ``dc`` and exponent ``p``."""
    delta = np.clip(dc - d, 0.0, None)
    inside = delta > 0
    if inside.sum() < 3:
        return float(np.sum(f**2)), 0.0, 0.0
    scale = float(delta.max()) ** p  # columns of comparable size (delta^p ~ 1e-16 m^2)
    x = np.column_stack([delta[inside] ** p / scale, -np.ones(inside.sum())])
    coef, *_ = np.linalg.lstsq(x, f[inside], rcond=None)
    coef[0] /= scale
    a, fad = float(max(coef[0], 0.0)), float(coef[1])
    if coef[0] < 0:
        fad = float(-np.mean(f[inside]))
    resid_in = f[inside] - (a * delta[inside] ** p - fad)
    cost = float(np.sum(resid_in**2) + np.sum(f[~inside] ** 2))
    return cost, a, fad
