"""Peer method: the established AM-AFM force inversion from amplitude and phase versus distance.

Implemented from the papers' equations (nothing copied):

* H. Hoelscher, "Quantitative measurement of tip-sample interactions in amplitude modulation
  atomic force microscopy", Appl. Phys. Lett. 89, 123109 (2006): for amplitudes large compared
  with the interaction range the averaged conservative force of one cycle is an Abel transform
  of ``F`` at the lower turning point ``D = d - A``, inverted by the Abel formula
  (:func:`hoelscher`).
* A. J. Katan, M. H. van Es, T. H. Oosterkamp, "Quantitative force versus distance measurements
  in amplitude modulation AFM: a novel force inversion technique", Nanotechnology 20, 165703
  (2009): the amplitude and phase define an equivalent frequency shift
  ``W_eq**2 = W**2 + B cos(phi) / A`` (``Omega(D) = W_eq - 1``; at resonance
  ``sqrt(1 + A0 cos(phi) / (Q A)) - 1``), inverted with the Sader--Jarvis formula
  (J. E. Sader, S. P. Jarvis, APL 84, 1801 (2004)) (:func:`sader_jarvis_katan`).
* A. F. Payam, D. Martin-Jimenez, R. Garcia, "Force reconstruction from tapping mode force
  microscopy experiments", Nanotechnology 26, 175706 (2015): compare both on the same data and
  evaluate the amplitude locally (``A(t)`` inside the integral), as done here.

Both assume the lever is in its steady state at every point (a quasi-static ramp) and a single
harmonic orbit. Dimensionless as the rest of the project: lengths in any unit ``L``, forces in
``k L``; ``W`` = drive frequency / f0, ``B`` = drive force (``B = A_f / Q`` at resonance).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["virial", "hoelscher", "sader_jarvis_katan", "turning_points"]


def virial(amplitude: ArrayLike, phase: ArrayLike, *, omega: float, drive: float
           ) -> NDArray[np.float64]:
    """Measured ``<F cos theta> = ((W**2 - 1) A + B cos(phi)) / 2`` (steady slow flow)."""
    a = np.asarray(amplitude, dtype=float)
    return 0.5 * ((omega * omega - 1.0) * a + drive * np.cos(np.asarray(phase, dtype=float)))


def turning_points(gap: ArrayLike, amplitude: ArrayLike) -> tuple[NDArray, NDArray]:
    """Lower turning points ``D = d - A`` sorted increasing, and the sort order."""
    d = np.asarray(gap, dtype=float) - np.asarray(amplitude, dtype=float)
    order = np.argsort(d, kind="stable")
    return d[order], order


def binned(d: NDArray, *values: NDArray, n_bins: int | None) -> tuple[NDArray, ...]:
    """Means of ``d`` and ``values`` in ``n_bins`` equal-width bins of sorted ``d``.

    The inversions differentiate along ``D``; measured turning points crowd and scatter (the
    amplitude noise moves them), so they are put on a uniform grid first, as one does with
    measured curves. Empty bins are dropped; ``None`` leaves the data as they are.
    """
    if n_bins is None:
        return (d, *values)
    edges = np.linspace(d[0], d[-1], n_bins + 1)
    idx = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins)
    keep = count > 0
    out = [np.bincount(idx, weights=v, minlength=n_bins)[keep] / count[keep]
           for v in (d, *values)]
    return tuple(out)


def _abel_like(x: NDArray, y: NDArray, weight_singular: bool = True) -> NDArray:
    """``I_j = int_{x_j}^{x_end} y(t) / sqrt(t - x_j) dt`` on a sorted grid.

    Trapezoid on ``[x_{j+1}, end]`` plus the singular first interval integrated exactly for
    ``y`` linear on it.
    """
    n = x.size
    out = np.zeros(n)
    for j in range(n - 1):
        h = x[j + 1] - x[j]
        if h <= 0:
            out[j] = out[j + 1] if j + 1 < n else 0.0
            continue
        # exact: int_0^h (y0 + (y1 - y0) s/h) / sqrt(s) ds = 2 y0 sqrt(h) + (2/3)(y1 - y0) sqrt(h)
        first = 2.0 * y[j] * math.sqrt(h) + (2.0 / 3.0) * (y[j + 1] - y[j]) * math.sqrt(h)
        t = x[j + 1:]
        g = y[j + 1:] / np.sqrt(t - x[j])
        out[j] = first + (np.trapezoid(g, t) if t.size > 1 else 0.0)
    return out


def hoelscher(gap: ArrayLike, amplitude: ArrayLike, phase: ArrayLike, *, omega: float,
              drive: float, n_bins: int | None = 200
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Hoelscher (2006) large-amplitude inversion.

    ``<F cos theta>(D) = (2 A)**-0.5 / pi * int_D^inf F(z) / sqrt(z - D) dz`` so
    ``G(D) = pi sqrt(2 A) <F cos theta>`` is the Abel transform of ``F`` and
    ``F(D) = -(1/pi) d/dD int_D^inf G(t) / sqrt(t - D) dt``.

    Parameters
    ----------
    gap, amplitude, phase : array-like, shape (m,)
        Rest gap ``d``, amplitude ``A`` and lag ``phi`` [rad] of a quasi-static approach.
    omega, drive : float
        ``W`` and ``B``.
    n_bins : int or None
        Uniform grid of turning points (:func:`binned`).

    Returns
    -------
    D, F : ndarray, shape (m,)
        Turning points (increasing) and the conservative force there.
    """
    a = np.asarray(amplitude, dtype=float)
    v = virial(a, phase, omega=omega, drive=drive)
    d, order = turning_points(gap, a)
    d, a, v = binned(d, a[order], v[order], n_bins=n_bins)
    g = math.pi * np.sqrt(2.0 * a) * v
    inner = _abel_like(d, g)
    return d, -np.gradient(inner, d) / math.pi


def sader_jarvis_katan(gap: ArrayLike, amplitude: ArrayLike, phase: ArrayLike, *,
                       omega: float, drive: float, n_bins: int | None = 200
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Katan et al. (2009) / Payam et al. (2015): Sader--Jarvis on the equivalent shift.

    ``Omega(D) = sqrt(W**2 + B cos(phi) / A) - 1`` and (``k = 1``)::

        F(D) = 2 int_D^inf [(1 + A**0.5 / (8 sqrt(pi (t - D)))) Omega(t)
                            - A**1.5 / sqrt(2 (t - D)) dOmega/dt] dt

    with the local amplitude ``A = A(t)``, on the uniform grid of :func:`binned`.
    Returns ``(D, F)`` as :func:`hoelscher`.
    """
    a = np.asarray(amplitude, dtype=float)
    ph = np.asarray(phase, dtype=float)
    w_eq2 = omega * omega + drive * np.cos(ph) / a
    shift = np.sqrt(np.maximum(w_eq2, 0.0)) - 1.0
    d, order = turning_points(gap, a)
    d, a, shift = binned(d, a[order], shift[order], n_bins=n_bins)
    dshift = np.gradient(shift, d)
    n = d.size
    out = np.zeros(n)
    for j in range(n - 1):
        t = d[j:]
        # regular part: 2 int Omega dt; singular parts with the exact first interval
        reg = 2.0 * np.trapezoid(shift[j:], t)
        s1 = _abel_like(t, a[j:] ** 0.5 * shift[j:] / (8.0 * math.sqrt(math.pi)))[0]
        s2 = _abel_like(t, a[j:] ** 1.5 * dshift[j:] / math.sqrt(2.0))[0]
        out[j] = reg + 2.0 * s1 - 2.0 * s2
    return d, out
