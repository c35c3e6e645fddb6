"""The identified force's 95 % band from the output-error fit: the exponent's profile included.

A band drawn from the Gauss--Newton covariance of the force coefficients alone (the exponent
and ``a0`` held at their estimates) claims a precision the data do not have: on the session-6
two-amplitude series its half-width for ``p`` was 0.013 where the profile-likelihood interval
is 0.36-0.80 wide, and the force at every sample moves with ``p`` and ``a0``. The band here is
the pointwise profile-likelihood band of ``F_ts(t)`` in the quadratic approximation about each
profile point:

    {F(t; theta) : chi2(theta) - chi2_min <= level}   (level: see below)

The level is SIMULTANEOUS by default: ``chi2_k(95 %)`` with ``k`` the force law's parameters
(``a0``, ``p`` and the coefficients; 9.49 for two terms), so that the whole true force curve,
not each sample separately, lies inside with 95 % probability (Scheffe's projection; the
chi2(1) level 3.841, ``simultaneous=False``, gives the pointwise band). Measured on the
session-6 two-amplitude series (p = 1.5, seed 2; 600 periods x 8 set-points, interval
1.29-1.93): the pointwise band held the true force on 67 % of the repulsive samples, the
simultaneous one on 99 %; at the true exponent the profile's fit is off the truth by 2.1 of
its own Gauss--Newton sd (median over the repulsive samples): one realisation's error is
one direction of the whole curve, which a pointwise band does not cover.

For the exponent's profile fit at ``p_k`` (every other parameter re-optimised, rise ``d_k``
above the minimum) the parameters with ``chi2 <= chi2_min + level`` and ``p = p_k`` form the
ellipsoid ``(theta - theta_k)^T J^T J (theta - theta_k) <= level - d_k``; its projection onto
``F(t)`` is ``F_k(t) +- sqrt((level - d_k) / dispersion) sd_k(t)`` with ``sd_k`` the
Gauss--Newton standard deviation of ``F(t)`` at fixed ``p`` (:func:`conditional_force`: the
delta method in ``a0`` and every force coefficient, ``K``, ``D``, ``B`` and the phases
marginalised by taking the covariance's sub-block). The band is the union of these intervals
over the profile points inside the level, plus the force interpolated where the profile
crosses the level (width zero there). At the estimate (``d = 0``) it is ``sqrt(level) sd``
(1.96 sd pointwise); at the crossings it shrinks to that exponent's force: no point outside
the likelihood region widens it, and a flat profile widens it as far as the data allow. The
profile walks stop a little above the chi2(1) level; beyond it the crossing is interpolated
to the next point (a scan point, 0.5 apart), which makes the simultaneous band's ends coarse.

The band is of the law evaluated on the denoised measured orbit (the orbit's own noise is not
in it), pointwise (not simultaneous over the record), and first order in ``a0`` (the force's
kink at the contact onset is not resolved by it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2 as chi2_dist

from .library import TermInput
from .output_error import OutputErrorResult, _bic

__all__ = ["conditional_force", "conditional_band", "profile_band", "band_level", "Z95"]

FloatArray = NDArray[np.float64]

#: two-sided 95 % normal quantile; ``Z95**2`` is the 1-dof chi2 level 3.841
Z95 = 1.959964


def band_level(n_params: int, *, simultaneous: bool = True) -> float:
    """The 95 % chi2 level (in units of the dispersion) of a band of a force with ``n_params``
    parameters: ``chi2_k(0.95)`` simultaneous, 3.841 pointwise."""
    return float(chi2_dist.ppf(0.95, max(int(n_params), 1))) if simultaneous else Z95**2


def _force_covariance(res: OutputErrorResult) -> FloatArray | None:
    """Covariance of ``[a0, c_1 .. c_m]`` at the fit's exponent (conditional on ``p`` when the
    fit left it free: the Schur complement); None when it is not finite."""
    h = res.law.n_head
    cov = np.asarray(res.covariance, float)
    idx = [3, *range(h, res.u.size)]
    c = cov[np.ix_(idx, idx)]
    if res.law.exponent_index is not None and math.isfinite(float(cov[4, 4])) \
            and cov[4, 4] > 0:
        cp = cov[idx, 4]
        c = c - np.outer(cp, cp) / float(cov[4, 4])
    if not np.all(np.isfinite(c)):
        return None
    return 0.5 * (c + c.T)


def conditional_force(res: OutputErrorResult, inputs: Sequence[TermInput]
                      ) -> list[tuple[FloatArray, FloatArray]]:
    """Force [k L_ref] of the fit ``res`` on every orbit and its Gauss--Newton standard
    deviation at the fit's exponent (NaN when the covariance is not finite).

    Parameters
    ----------
    res : OutputErrorResult
        A fit (free or fixed exponent) with its covariance.
    inputs : sequence of TermInput
        One per observation (the denoised orbits; their ``a0`` is ignored).

    Returns
    -------
    list of (force, sd)
        Each shape (n,) of that observation, dimensionless.
    """
    lib, a0 = res.library, res.a0
    c = np.asarray(res.u[res.law.n_head:], float)
    cov = _force_covariance(res)
    da = 1e-6 * max(abs(a0), 1e-3)
    out = []
    for ti in inputs:
        th = lib.evaluate(TermInput(z=ti.z, zdot=ti.zdot, x=ti.x, a0=a0))
        f = th @ c
        if cov is None:
            out.append((f, np.full_like(f, np.nan)))
            continue
        fp = lib.evaluate(TermInput(z=ti.z, zdot=ti.zdot, x=ti.x, a0=a0 + da)) @ c
        fm = lib.evaluate(TermInput(z=ti.z, zdot=ti.zdot, x=ti.x, a0=a0 - da)) @ c
        g = np.column_stack([(fp - fm) / (2 * da), th])
        var = np.einsum("ij,jk,ik->i", g, cov, g)
        out.append((f, np.sqrt(np.maximum(var, 0.0))))
    return out


def conditional_band(res: OutputErrorResult, inputs: Sequence[TermInput], *,
                     simultaneous: bool = True) -> dict[str, list[FloatArray]]:
    """Force and 95 % band of ONE fit with its exponent taken as known (a fixed exponent:
    the band is conditional on that choice; simultaneous over ``a0`` and the coefficients by
    default, :func:`band_level`). Keys ``force``, ``lo``, ``hi``: one array (n,) per
    observation, dimensionless."""
    k = math.sqrt(band_level(1 + res.law.library.n_terms, simultaneous=simultaneous))
    out: dict[str, list[FloatArray]] = {"force": [], "lo": [], "hi": []}
    for f, sd in conditional_force(res, inputs):
        out["force"].append(f)
        out["lo"].append(f - k * sd)
        out["hi"].append(f + k * sd)
    return out


def profile_band(expo: dict[str, Any], best: OutputErrorResult,
                 inputs: Sequence[TermInput], *, simultaneous: bool = True
                 ) -> dict[str, list[FloatArray]] | None:
    """The 95 % profile-likelihood band of the force (module docstring).

    Parameters
    ----------
    expo : dict
        :class:`~afmlearn.identify.output_error.OutputErrorProfile`'s table: ``profile``
        (n, 2) exponent and score, ``fits`` (exponent -> fit), ``level``, ``dispersion``.
    best : OutputErrorResult
        The estimate (its score is the profile's minimum or near it).
    inputs : sequence of TermInput
        One per observation (the denoised orbits).
    simultaneous : bool
        The level ``chi2_k(0.95)`` over the law's ``k`` parameters (``a0``, ``p``, the
        coefficients of ``best``) instead of chi2(1) (:func:`band_level`).

    Returns
    -------
    dict or None
        ``lo``, ``hi``: one array (n,) per observation, dimensionless, and ``exponents``
        (the profile points that entered); None without a usable profile.
    """
    prof = np.asarray(expo.get("profile", np.empty((0, 2))), float)
    fits: dict[float, OutputErrorResult] = dict(expo.get("fits") or {})
    if prof.size == 0 or not fits:
        return None
    disp = float(expo["dispersion"])
    level = band_level(2 + best.law.library.n_terms, simultaneous=simultaneous) * disp
    ok = np.isfinite(prof[:, 1])
    p, s = prof[ok, 0], prof[ok, 1]
    order = np.argsort(p)
    p, s = p[order], s[order]
    rise = s - float(np.min(s))
    lo = [np.full(ti.z.size, np.inf) for ti in inputs]
    hi = [np.full(ti.z.size, -np.inf) for ti in inputs]
    used: list[float] = []

    def widen(fs: list[tuple[FloatArray, FloatArray]], room: float) -> None:
        k = math.sqrt(max(room, 0.0) / disp)
        for i, (f, sd) in enumerate(fs):
            w = np.where(np.isfinite(sd), k * sd, 0.0)
            lo[i] = np.minimum(lo[i], f - w)
            hi[i] = np.maximum(hi[i], f + w)

    forces: dict[float, list[tuple[FloatArray, FloatArray]]] = {}

    def at(k: float) -> list[tuple[FloatArray, FloatArray]] | None:
        key = round(float(k), 6)
        if key not in forces:
            r = fits.get(key)
            if r is None:
                return None
            # every point's covariance on the estimate's dispersion (the level's)
            scale = disp / r.dispersion
            forces[key] = [(f, sd * math.sqrt(scale)) for f, sd in conditional_force(r, inputs)]
        return forces[key]

    inside = np.flatnonzero(rise <= level)
    for j in inside:
        fs = at(p[j])
        if fs is not None:
            widen(fs, level - rise[j])
            used.append(float(p[j]))
    # the interval's ends: the force interpolated between the last point inside and the first
    # outside, where sqrt(rise) crosses sqrt(level) (as the interval's ends are found)
    for j in inside:
        for nb in (j - 1, j + 1):
            if not (0 <= nb < p.size) or rise[nb] <= level:
                continue
            a, b = at(p[j]), at(p[nb])
            if a is None or b is None:
                continue
            ra, rb = math.sqrt(rise[j]), math.sqrt(rise[nb])
            w = (math.sqrt(level) - ra) / (rb - ra) if rb > ra else 0.0
            widen([((1 - w) * fa + w * fb, np.zeros_like(fa))
                   for (fa, _), (fb, _) in zip(a, b, strict=True)], 0.0)
    # the estimate itself (its score may sit just below the table's minimum)
    d_best = max(_bic(best) - float(np.min(s)), 0.0)
    widen([(f, sd * math.sqrt(disp / best.dispersion))
           for f, sd in conditional_force(best, inputs)], level - d_best)
    if best.exponent is not None:
        used.append(float(best.exponent))
    return {"lo": lo, "hi": hi, "exponents": sorted(set(used))}
