"""Forecast strategies: how a sequence network turns one period of input into ``horizon`` periods.

Both strategies share one read-out: at every sample ``t`` of the input period the features
``[h_t, h_T]`` (the hidden state at ``t`` and the last hidden state, which summarises the whole
period) go through one linear layer. The output at ``t`` predicts the deflection at the same
phase ``t`` of the following period(s), optionally as a correction to a ``base`` forecast made
from the measured period alone: the periodic continuation ``x(t + k P) = x(t)`` or its
per-harmonic filtered version (``residual`` and ``spectral_skip`` of
:class:`afmlearn.qrnn.module.OrbitModule`).

`DirectForecast`
    The read-out has ``horizon`` outputs per sample: all predicted periods come out at once from
    one pass over the measured period. Errors do not compound; the read-out learns each lead
    separately.
`AutoregressiveForecast`
    The read-out has one output per sample (the next period). The predicted period replaces the
    deflection channel of the input and the network runs again, ``horizon`` times; the other input
    channels (constant or periodic per window, e.g. the drive frequency) are carried over
    unchanged. The same one-step map serves every lead, so it extrapolates beyond the trained
    horizon, but its errors compound.

Shapes: ``x`` is ``(batch, P, n_features)`` (``P`` samples per period), predictions are
``(batch, horizon * P)`` with period ``k`` in ``[:, k * P:(k + 1) * P]``, all in the normalised
units of the data module.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import final

import torch
from torch import Tensor

__all__ = ["AbstractForecast", "DirectForecast", "AutoregressiveForecast"]

#: ``step(x) -> (outputs (B, P, n_out), hidden (B, P, H))``: one pass of network + read-out
Step = Callable[[Tensor], tuple[Tensor, Tensor]]
#: ``base(u) -> (B, P, n_out)``: the skip forecast from the deflection ``u`` (B, P) of a period
Base = Callable[[Tensor], Tensor]


class AbstractForecast(abc.ABC):
    """How the read-out is sized and how it is rolled out over the horizon."""

    @abc.abstractmethod
    def outputs_per_step(self, horizon: int) -> int:
        """Number of read-out outputs per input sample for a forecast of ``horizon`` periods."""

    @abc.abstractmethod
    def rollout(self, step: Step, x: Tensor, *, horizon: int, deflection_channel: int,
                base: Base | None) -> tuple[Tensor, Tensor]:
        """Predict ``horizon`` periods after the input period.

        Parameters
        ----------
        step : callable
            ``step(x)`` runs network and read-out on ``x`` (shape (B, P, F)) and returns the
            read-out ``(B, P, outputs_per_step(horizon))`` and the hidden states ``(B, P, H)``.
        x : Tensor, shape (B, P, F)
            One period of input, normalised.
        horizon : int
            Periods to predict (>= 1).
        deflection_channel : int
            Index of the deflection among the ``F`` input channels.
        base : callable or None
            ``base(u)`` (``u``: the deflection channel of the period fed in, (B, P)) gives the
            skip forecast ``(B, P, outputs_per_step(horizon))`` the read-out corrects; None:
            the read-out is the forecast itself.

        Returns
        -------
        y : Tensor, shape (B, horizon * P)
            Predicted deflection, normalised.
        hidden : Tensor, shape (B, P, H)
            Hidden states of the network on the measured input period.
        """

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


@final
class DirectForecast(AbstractForecast):
    """All ``horizon`` periods from one pass (``horizon`` read-out outputs per sample)."""

    def outputs_per_step(self, horizon: int) -> int:
        return horizon

    def rollout(self, step: Step, x: Tensor, *, horizon: int, deflection_channel: int,
                base: Base | None) -> tuple[Tensor, Tensor]:
        out, hidden = step(x)                                  # (B, P, horizon)
        if base is not None:
            out = out + base(x[:, :, deflection_channel])
        # (B, P, horizon) -> (B, horizon, P) -> (B, horizon * P)
        return out.transpose(1, 2).reshape(x.shape[0], -1), hidden


@final
class AutoregressiveForecast(AbstractForecast):
    """One period per pass; the prediction is fed back ``horizon`` times."""

    def outputs_per_step(self, horizon: int) -> int:
        return 1

    def rollout(self, step: Step, x: Tensor, *, horizon: int, deflection_channel: int,
                base: Base | None) -> tuple[Tensor, Tensor]:
        periods = []
        hidden0 = None
        current = x
        for _ in range(horizon):
            out, hidden = step(current)                        # (B, P, 1)
            if hidden0 is None:
                hidden0 = hidden
            if base is not None:
                out = out + base(current[:, :, deflection_channel])
            periods.append(out[..., 0])
            current = torch.cat([current[..., :deflection_channel], out,
                                 current[..., deflection_channel + 1:]], dim=-1)
        assert hidden0 is not None
        return torch.cat(periods, dim=1), hidden0
