"""Orbit-forecast losses of :class:`afmlearn.qrnn.module.OrbitModule` (strategy objects).

`MSEOrbitLoss`
    Mean squared error over all windows and samples. Dominated by the few windows whose next
    periods differ most from the input (transients, a sweep point just after a jump): on the
    issue-15 data a model trained on it lowered the MSE below the persistence forecast's
    (0.042 vs 0.049, held-out cantilevers) while the *typical* window got worse (median NRMSE
    of period 1: 0.024 vs 0.015) -- the mean NRMSE of design.md section 4 was 9 % worse than
    persistence.
`PeriodNRMSELoss` (default)
    The mean over windows and predicted periods of ``RMS(pred - true) / span(true)``: exactly the
    metric the forecast is judged by (design.md section 4, :func:`afmlearn.qrnn.evaluate.
    nrmse_per_period`), so every window counts alike. Its gradient does not vanish for small
    errors (``d RMS / d e = e / (n RMS)``), so the steady windows, where the periodic
    continuation is already good, are not traded for the outliers.

Shapes: ``pred`` and ``true`` are ``(batch, horizon * P)`` in the data module's normalised
units, period ``k`` in ``[:, k * P:(k + 1) * P]``; the loss is a scalar tensor.
"""

from __future__ import annotations

import abc
from typing import final

import torch
from torch import Tensor

__all__ = ["AbstractOrbitLoss", "MSEOrbitLoss", "PeriodNRMSELoss"]


class AbstractOrbitLoss(abc.ABC):
    """Loss of the predicted periods against the recorded ones."""

    @abc.abstractmethod
    def __call__(self, pred: Tensor, true: Tensor, *, horizon: int) -> Tensor:
        """Scalar loss of ``pred`` vs ``true`` (both ``(B, horizon * P)``, normalised)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


@final
class MSEOrbitLoss(AbstractOrbitLoss):
    """Mean squared error over every sample of every window."""

    def __call__(self, pred: Tensor, true: Tensor, *, horizon: int) -> Tensor:
        return torch.mean((pred - true) ** 2)


@final
class PeriodNRMSELoss(AbstractOrbitLoss):
    """Mean over windows and periods of ``RMS(pred - true) / (max(true) - min(true))``.

    Parameters
    ----------
    eps : float, default 1e-8
        Added to the mean square before the square root (a finite gradient at zero error) and
        the floor of the span (a flat period), in normalised units squared / normalised units.
    """

    def __init__(self, *, eps: float = 1e-8) -> None:
        if not float(eps) > 0.0:
            raise ValueError(f"eps must be > 0, got {eps}")
        self.eps = float(eps)

    def __call__(self, pred: Tensor, true: Tensor, *, horizon: int) -> Tensor:
        n = pred.shape[0]
        p = pred.reshape(n, int(horizon), -1)
        t = true.reshape(n, int(horizon), -1)
        rms = torch.sqrt(torch.mean((p - t) ** 2, dim=-1) + self.eps)
        span = (t.amax(dim=-1) - t.amin(dim=-1)).clamp_min(self.eps)
        return torch.mean(rms / span)

    def __repr__(self) -> str:
        return f"PeriodNRMSELoss(eps={self.eps:g})"
