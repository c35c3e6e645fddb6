"""Causes of a non-sinusoidal free oscillation, each a linear extension of the baseline.

The baseline (a linear one-mode lever oscillating freely, no force) predicts the record as
``y = c + A(t) cos(phi(t))``: the demodulated fundamental plus an offset, no harmonics. A
cause adds columns ``g_j(t)`` built from the fundamental's state (amplitude, phase, time) with
coefficients shared by the whole record: ``y = c + A cos(phi) + sum_j theta_j g_j``. With all
``theta = 0`` every cause is the baseline (nested), so fitting on one span and predicting
another measures what the cause explains that the baseline does not.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afmlearn.freeosc.demodulate import Demodulation

__all__ = ["AbstractCause"]

FloatArray = NDArray[np.float64]


class AbstractCause(abc.ABC):
    """A cause as model columns on top of the baseline; one abstract hook, `_columns`.

    Fitted attributes (after `fit`): ``offset_`` (record units), ``coef_`` (shape
    (n_columns,), units per the subclass's columns).
    """

    #: cause name (design.md section 3 vocabulary, or a name stated in docs/real_data.md)
    name: ClassVar[str]
    #: short statement of the model extension
    equation: ClassVar[str]

    @abc.abstractmethod
    def _columns(self, demod: Demodulation) -> FloatArray:
        """Columns ``g_j(t)``, shape (n, n_columns) (n_columns may be 0), record units."""

    def fit(self, y: ArrayLike, demod: Demodulation) -> AbstractCause:
        """Least squares of ``y - A cos(phi)`` on ``[1, g_1 .. g_p]``.

        Parameters
        ----------
        y : array-like, shape (n,)
            The record on the fitted span.
        demod : Demodulation
            Its demodulated fundamental on the same samples.

        Returns
        -------
        self
        """
        y = np.asarray(y, dtype=float)
        if y.shape != demod.phase.shape:
            raise ValueError(f"y must have shape {demod.phase.shape}, got {y.shape}")
        design = np.column_stack([np.ones_like(y), self._columns(demod)])
        coef, *_ = np.linalg.lstsq(design, y - demod.fundamental(), rcond=None)
        self.offset_ = float(coef[0])
        self.coef_ = np.asarray(coef[1:], dtype=float)
        return self

    def predict(self, demod: Demodulation) -> FloatArray:
        """Predicted record, shape (n,), record units (call `fit` first)."""
        if not hasattr(self, "coef_"):
            raise ValueError(f"{type(self).__name__} is not fitted: call fit first")
        cols = self._columns(demod)
        return self.offset_ + demod.fundamental() + cols @ self.coef_
