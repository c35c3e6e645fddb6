"""Sequence networks with one interface: QRNN and its LSTM / GRU baselines.

Every network maps a batch of input sequences to the hidden activations of its last layer,
``encode(x: (batch, time, input_size)) -> (batch, time, hidden_size)``; prediction and
classification heads live in the LightningModule (``afmlearn.qrnn.module``), which receives a
network object. The hidden activations are what the interpretation (``afmlearn.qrnn.interpret``)
plots against the drive frequency. Baselines have the same hidden size and number of layers,
so comparisons are at equal width.
"""

from __future__ import annotations

import abc
import typing

from torch import Tensor, nn

from afmlearn.qrnn.layer import QRNN, AbstractPooling, _check_int, _check_prob

__all__ = ["AbstractSequenceNet", "GRUNet", "LSTMNet", "QRNNNet"]


class AbstractSequenceNet(nn.Module, abc.ABC):
    """Batch-first sequence network exposing the hidden activations of its last layer.

    Attributes
    ----------
    input_size : int
        Number of input features.
    hidden_size : int
        Number of hidden units of the last layer (width of `encode`'s output).
    num_layers : int
        Number of stacked recurrent layers.
    """

    input_size: int
    hidden_size: int
    num_layers: int

    def _check_sizes(self, input_size: int, hidden_size: int, num_layers: int) -> None:
        self.input_size = _check_int("input_size", input_size, 1)
        self.hidden_size = _check_int("hidden_size", hidden_size, 1)
        self.num_layers = _check_int("num_layers", num_layers, 1)

    def _check_x(self, x: Tensor) -> None:
        if x.dim() != 3 or x.shape[-1] != self.input_size:
            raise ValueError(f"x must have shape (batch, time, {self.input_size}); got "
                             f"{tuple(x.shape)}")

    @abc.abstractmethod
    def encode(self, x: Tensor) -> Tensor:
        """Hidden activations of the last layer.

        Parameters
        ----------
        x : Tensor, shape (batch, time, input_size)
            Input sequences (dimensionless features).

        Returns
        -------
        h : Tensor, shape (batch, time, hidden_size)
            Hidden activations of the last layer at every time step.
        """

    def forward(self, x: Tensor) -> Tensor:
        """Same as `encode` (``(batch, time, input_size) -> (batch, time, hidden_size)``)."""
        return self.encode(x)


@typing.final
class QRNNNet(AbstractSequenceNet):
    """Stacked QRNN (`afmlearn.qrnn.layer.QRNN`).

    Parameters
    ----------
    input_size, hidden_size : int
        Input features and hidden units per layer (``>= 1``).
    num_layers : int
        Stacked layers ``>= 1``.
    window : int
        Causal convolution width ``>= 1`` of the first layer.
    upper_window : int, optional
        Width of the layers above it (None: ``window``); see `afmlearn.qrnn.layer.QRNN`.
    pooling : AbstractPooling, optional
        `FPooling`, `FOPooling` (default) or `IFOPooling`.
    zoneout : float
        Zoneout on the forget gate, in [0, 1).
    dropout : float
        Dropout between layers, in [0, 1).
    """

    def __init__(self, input_size: int, hidden_size: int, *, num_layers: int = 2,
                 window: int = 2, upper_window: int | None = None,
                 pooling: AbstractPooling | None = None,
                 zoneout: float = 0.0, dropout: float = 0.0) -> None:
        super().__init__()
        self._check_sizes(input_size, hidden_size, num_layers)
        self.qrnn = QRNN(input_size, hidden_size, num_layers=num_layers, window=window,
                         upper_window=upper_window, pooling=pooling, zoneout=zoneout,
                         dropout=dropout)

    def encode(self, x: Tensor) -> Tensor:
        self._check_x(x)
        h, _ = self.qrnn(x)
        return h


class _TorchRecurrentNet(AbstractSequenceNet):
    """A `torch.nn` recurrent layer stack (batch-first) as a sequence net; see LSTMNet/GRUNet."""

    _rnn_type: type[nn.RNNBase]

    def __init__(self, input_size: int, hidden_size: int, *, num_layers: int = 2,
                 dropout: float = 0.0) -> None:
        super().__init__()
        self._check_sizes(input_size, hidden_size, num_layers)
        self.rnn = self._rnn_type(input_size, hidden_size, num_layers=num_layers,
                                  batch_first=True, dropout=_check_prob("dropout", dropout))

    def encode(self, x: Tensor) -> Tensor:
        self._check_x(x)
        h, _ = self.rnn(x)
        return h


@typing.final
class LSTMNet(_TorchRecurrentNet):
    """Baseline: `torch.nn.LSTM` (batch-first) of the given size.

    Parameters
    ----------
    input_size, hidden_size : int
        Input features and hidden units per layer (``>= 1``).
    num_layers : int
        Stacked layers ``>= 1``.
    dropout : float
        Dropout between layers, in [0, 1).
    """

    _rnn_type = nn.LSTM


@typing.final
class GRUNet(_TorchRecurrentNet):
    """Baseline: `torch.nn.GRU` (batch-first) of the given size; parameters as `LSTMNet`."""

    _rnn_type = nn.GRU
