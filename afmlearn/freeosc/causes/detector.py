"""Detector nonlinearity: an instantaneous map of the true motion, ``y = x + b2 x^2 + b3 x^3``.

With ``x = A cos(phi)``: ``x^2 = A^2/2 (1 + cos 2phi)``, ``x^3 = A^3/4 (3 cos phi + cos 3phi)``
(the ``cos phi`` part is inside the measured fundamental). Signature: harmonic n scales as
``A^n``, its phase is locked to ``n phi`` (``arg R_n`` = 0 or pi), not shaped by the lever's
transfer function, and the dc level moves with ``A^2`` by the same coefficient as the 2nd
harmonic (ratio +1).
"""

from __future__ import annotations

from typing import final

import numpy as np

from afmlearn.freeosc.causes.base import AbstractCause, FloatArray
from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["DetectorNonlinearity"]


@final
class DetectorNonlinearity(AbstractCause):
    """Columns ``A^2/2 (1 + cos 2phi)`` and ``A^3/4 cos 3phi``; ``coef_ = [b2, b3]`` in
    1/record unit and 1/record unit^2."""

    name = "detector_nonlinearity"
    equation = "y = c + x + b2 x^2 + b3 x^3, x = A cos(phi)"

    def _columns(self, demod: Demodulation) -> FloatArray:
        a, p = demod.amplitude, demod.phase
        return np.column_stack([a**2 / 2 * (1 + np.cos(2 * p)), a**3 / 4 * np.cos(3 * p)])
