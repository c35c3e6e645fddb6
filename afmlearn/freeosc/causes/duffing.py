"""Nonlinear (Duffing) stiffness of the lever itself: ``k x (1 + beta x^2)``.

Only odd harmonics (a 3rd through ``H(3 Omega)`` = -1/8 on resonance) and an
amplitude-dependent frequency ``Delta f / f = 3 beta A^2 / 8``; it cannot make a 2nd harmonic.
"""

from __future__ import annotations

import math
from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.causes.electrostatic import transfer
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["DuffingStiffness"]


@final
class DuffingStiffness(AbstractCause):
    """Column ``-A^3/4 Re(H(3) e^{3 i phi})``; ``coef_ = [beta]`` in 1/record unit^2.

    Parameters
    ----------
    quality_factor : float, default inf
        Q > 0 of the lever (inf: real transfer function).
    """

    name = "nonlinear_stiffness"
    equation = "y = c + A cos(phi) - beta H(3) x^3 |_(3 phi)"

    def __init__(self, *, quality_factor: float = math.inf) -> None:
        if not quality_factor > 0:
            raise ValueError(f"quality_factor must be > 0, got {quality_factor!r}")
        self.quality_factor = quality_factor

    def _columns(self, demod: Demodulation) -> FloatArray:
        h3 = transfer(3, quality_factor=self.quality_factor)
        return (-demod.amplitude**3 / 4 * (h3 * np.exp(3j * demod.phase)).real)[:, None]
