"""Detector nonlinearity: an instantaneous map of the true motion, ``y = x + sum_k b_k x^k``.

With ``x = A cos(phi)``, ``x^k`` holds harmonics 0..k; its ``cos phi`` part is inside the
measured fundamental and is taken out of the column (e.g. ``x^2 = A^2/2 (1 + cos 2phi)``,
``x^3 -> A^3/4 cos 3phi``). Signature: harmonic n scales as ``A^n``, its phase is locked to
``n phi`` (``arg R_n`` = 0 or pi), not shaped by the lever's transfer function, and the dc
level moves with ``A^2`` by the same coefficient as the 2nd harmonic (ratio +1). A smooth map
(an interferometer's ``cos(theta + kappa x)``, a photodiode's saturation) has terms beyond
``x^3``: ``order`` sets how many.
"""

from __future__ import annotations

import math
from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["DetectorNonlinearity"]


@final
class DetectorNonlinearity(AbstractCause):
    """Columns ``x^k`` minus their ``cos phi`` part, k = 2..order; ``coef_ = [b2 .. b_order]``
    in 1/record unit^(k-1).

    Parameters
    ----------
    order : int, default 3
        Highest power of the map, in [2, 9].
    """

    name = "detector_nonlinearity"
    equation = "y = c + x + b2 x^2 + b3 x^3 (+ ...), x = A cos(phi)"

    def __init__(self, *, order: int = 3) -> None:
        if isinstance(order, bool) or not isinstance(order, int) or not 2 <= order <= 9:
            raise ValueError(f"order must be an integer in [2, 9], got {order!r}")
        self.order = order

    def _columns(self, demod: Demodulation) -> FloatArray:
        a, p = demod.amplitude, demod.phase
        x = a * np.cos(p)
        cols = []
        for k in range(2, self.order + 1):
            # cos^k phi has cos phi coefficient C(k, (k-1)/2) / 2^(k-1) for odd k, 0 for even k
            fund = math.comb(k, (k - 1) // 2) / 2 ** (k - 1) if k % 2 else 0.0
            cols.append(x**k - fund * a**k * np.cos(p))
        return np.column_stack(cols)
