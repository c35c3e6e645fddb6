"""The drive phase of a steady orbit, in closed form from its harmonics (one helper for the
identifier's and the diagnosis' output-error fits).

A steady orbit started at drive phase ``phi`` has harmonics ``X0_k e^{-i k phi}``, where ``X0``
are those of the same orbit started at phase 0. Matching measured harmonics ``Y_k`` by least
squares in ``phi`` is one real function of one angle: it is evaluated on a grid with one FFT and
polished by Newton steps, with an optional Gaussian prior (a recorded drive phase and its
uncertainty).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["align_phase", "wrap_angle"]


def wrap_angle(a: Any) -> Any:
    """Angle(s) [rad] wrapped to ``(-pi, pi]``: a float for a number, else an array."""
    if isinstance(a, float):        # the hot scalar path (Newton steps on a phase)
        return float(math.pi - (math.pi - a) % (2 * math.pi))
    return np.pi - np.mod(np.pi - np.asarray(a, float), 2 * np.pi) if np.ndim(a) else \
        float(math.pi - (math.pi - float(a)) % (2 * math.pi))


def align_phase(X0: NDArray[np.complex128], Y: NDArray[np.complex128], sigma: ArrayLike,
                prior: tuple[float, float] | None = None) -> float:
    """Drive phase ``phi`` [rad] minimising ``sum_k |X0_k e^{-i k phi} - Y_k|^2 / sigma_k^2``
    over the harmonics ``k >= 1``, plus ``((phi - mean) / sd)^2`` for a ``prior`` ``(mean, sd)``.

    Parameters
    ----------
    X0 : complex array, shape (n,)
        Harmonics ``k = 0 .. n-1`` of the orbit started at drive phase 0.
    Y : complex array, shape (n',)
        Measured harmonics (the first ``min(n, n')`` are used).
    sigma : float or array, shape (>= min(n, n'),)
        Noise of one real harmonic coefficient: one number, or one per harmonic number.
    prior : (float, float), optional
        Mean and standard deviation [rad] of a recorded drive phase.

    Returns
    -------
    float
        ``phi`` in ``(-pi, pi]``: a grid of ``max(256, 4 n)`` phases (one FFT), then Newton steps.
    """
    k = np.arange(1, min(X0.size, Y.size))
    s = np.asarray(sigma, float)
    w = 1.0 / (s[k] if s.ndim else s) ** 2
    a = w * np.conj(Y[k]) * X0[k]            # cost = const - 2 Re sum a_k e^{-i k phi}
    m = max(256, 4 * k.size)
    full = np.zeros(m, complex)
    full[k] = a
    g = np.real(np.fft.fft(full))             # g_j = Re sum_k a_k e^{-i k 2 pi j / m}
    phis = 2 * np.pi * np.arange(m) / m
    f = -2.0 * g
    if prior is not None:
        f = f + (wrap_angle(phis - prior[0]) / prior[1]) ** 2
    phi = float(phis[int(np.argmin(f))])
    for _ in range(8):
        e = a * np.exp(-1j * k * phi)
        d1 = -2.0 * float(np.real(np.sum(-1j * k * e)))
        d2 = -2.0 * float(np.real(np.sum(-(k**2) * e)))
        if prior is not None:
            d1 += 2.0 * wrap_angle(phi - prior[0]) / prior[1] ** 2
            d2 += 2.0 / prior[1] ** 2
        if d2 <= 0:
            break
        step = max(min(d1 / d2, 0.05), -0.05)
        phi -= step
        if abs(step) < 1e-13:
            break
    return float(wrap_angle(phi))
