"""Quasi-recurrent layer (Bradbury, Merity, Xiong, Socher 2016) in plain PyTorch.

A QRNN layer is a masked (causal) 1-D convolution over time followed by a cheap element-wise
recurrence ("pooling"), physics.md section 6. With window ``k`` and input ``x_t``:

    Z = tanh(W_z * X),  F = sigmoid(W_f * X),  O = sigmoid(W_o * X),  I = sigmoid(W_i * X),

where ``W * X`` at time ``t`` sees only ``x_{t-k+1} .. x_t`` (zeros, or the carried inputs of a
stream, before the start). The convolution is computed as one matrix product of the ``k``
time-shifted copies of ``x`` concatenated along features (identical to a left-padded
``conv1d``) with all gates' weights side by side, in time-major storage: the gates are
``(batch, time, hidden)`` views of it.
Pooling strategies (objects, see `AbstractPooling`):

- `FPooling`:   ``c_t = f_t * c_{t-1} + (1 - f_t) * z_t``,  ``h_t = c_t``;
- `FOPooling`:  same ``c_t``,  ``h_t = o_t * c_t``;
- `IFOPooling`: ``c_t = f_t * c_{t-1} + i_t * z_t``,  ``h_t = o_t * c_t``.

Gate convention
---------------
``f`` is the paper's forget gate: ``f`` near 1 *remembers* the previous state, ``f`` near 0
replaces it by ``z``. Salesforce's old CUDA kernel takes ``1 - f`` instead; do not mix the two
when porting weights.

Zoneout
-------
On ``F`` during training, as in the paper: ``F = 1 - dropout(1 - F)`` with an unscaled
Bernoulli mask (a zoned-out unit keeps ``c_{t-1}`` exactly); in evaluation ``1 - F`` is
multiplied by its expectation ``1 - zoneout`` (as the reference implementation does).

Streaming
---------
`QRNN.stream` carries both the cell states and the last ``window - 1`` inputs of every layer,
so feeding a long sequence in pieces gives the same output as one call (in evaluation mode).
`QRNN.forward` starts from zero inputs before ``t = 0`` (it re-reads nothing).

Shapes are batch-first ``(batch, time, features)``; all quantities dimensionless.
"""

from __future__ import annotations

import abc
import typing
from typing import NamedTuple

import torch
from torch import Tensor, nn

from afmlearn.qrnn.scan import AbstractScan, ChunkedScan

__all__ = [
    "AbstractPooling",
    "FOPooling",
    "FPooling",
    "IFOPooling",
    "QRNN",
    "QRNNCarry",
    "QRNNLayer",
]


class AbstractPooling(abc.ABC):
    """How the gates are pooled over time (f-, fo- or ifo-pooling).

    Parameters
    ----------
    scan : AbstractScan
        Solver of the recurrence ``c_t = a_t c_{t-1} + b_t``: `ChunkedScan` (fast, default) or
        `ReferenceScan` (readable loop).
    """

    #: number of gate blocks the convolution produces (``z``, ``f`` and the extra gates)
    n_gates: typing.ClassVar[int]

    def __init__(self, *, scan: AbstractScan | None = None) -> None:
        self.scan = ChunkedScan() if scan is None else scan

    @abc.abstractmethod
    def __call__(self, z: Tensor, f: Tensor, extra: tuple[Tensor, ...],
                 c0: Tensor | None) -> tuple[Tensor, Tensor]:
        """Pool the activated gates.

        Parameters
        ----------
        z : Tensor, shape (batch, time, hidden)
            Candidates ``tanh(W_z * X)``.
        f : Tensor, shape (batch, time, hidden)
            Forget gates in [0, 1] (1 = remember), zoneout already applied.
        extra : tuple of Tensor, each shape (batch, time, hidden)
            The other ``n_gates - 2`` gates after the sigmoid, in order ``(o, i)``.
        c0 : Tensor, shape (batch, hidden), or None
            Cell state before the first step (zeros when None).

        Returns
        -------
        h : Tensor, shape (batch, time, hidden)
            Hidden outputs.
        c : Tensor, shape (batch, time, hidden)
            Cell states.
        """

    def __repr__(self) -> str:
        return f"{type(self).__name__}(scan={self.scan!r})"


@typing.final
class FPooling(AbstractPooling):
    """f-pooling: ``c_t = f_t c_{t-1} + (1 - f_t) z_t``, ``h_t = c_t`` (2 gate blocks)."""

    n_gates = 2

    def __call__(self, z, f, extra, c0):
        c = self.scan(f, torch.addcmul(z, f, z, value=-1.0), c0)  # b = (1 - f) z
        return c, c


@typing.final
class FOPooling(AbstractPooling):
    """fo-pooling: ``c_t = f_t c_{t-1} + (1 - f_t) z_t``, ``h_t = o_t c_t`` (3 gate blocks)."""

    n_gates = 3

    def __call__(self, z, f, extra, c0):
        (o,) = extra
        c = self.scan(f, torch.addcmul(z, f, z, value=-1.0), c0)  # b = (1 - f) z
        return o * c, c


@typing.final
class IFOPooling(AbstractPooling):
    """ifo-pooling: ``c_t = f_t c_{t-1} + i_t z_t``, ``h_t = o_t c_t`` (4 gate blocks)."""

    n_gates = 4

    def __call__(self, z, f, extra, c0):
        o, i = extra
        c = self.scan(f, i * z, c0)
        return o * c, c


def _check_int(name: str, value: object, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}; got {value!r}")
    return value


def _check_prob(name: str, value: object) -> float:
    v = float(value)  # type: ignore[arg-type]
    if not 0.0 <= v < 1.0:
        raise ValueError(f"{name} must be in [0, 1); got {value!r}")
    return v


@typing.final
class QRNNLayer(nn.Module):
    """One quasi-recurrent layer: masked causal convolution + pooling (see module docstring).

    Parameters
    ----------
    input_size : int
        Number of input features ``>= 1``.
    hidden_size : int
        Number of hidden units ``>= 1``.
    window : int
        Width ``k >= 1`` of the causal convolution (time steps seen per output; 1: a
        time-distributed projection, as the upper layers of Merity et al.'s QRNN language
        model).
    pooling : AbstractPooling
        `FPooling`, `FOPooling` (default) or `IFOPooling`.
    zoneout : float
        Zoneout probability on the forget gate, in [0, 1).
    """

    def __init__(self, input_size: int, hidden_size: int, *, window: int = 2,
                 pooling: AbstractPooling | None = None, zoneout: float = 0.0) -> None:
        super().__init__()
        self.input_size = _check_int("input_size", input_size, 1)
        self.hidden_size = _check_int("hidden_size", hidden_size, 1)
        self.window = _check_int("window", window, 1)
        pooling = FOPooling() if pooling is None else pooling
        if not isinstance(pooling, AbstractPooling):
            raise ValueError(f"pooling must be an AbstractPooling (FPooling, FOPooling, "
                             f"IFOPooling); got {pooling!r}")
        self.pooling = pooling
        self.zoneout = _check_prob("zoneout", zoneout)
        n_in = self.window * self.input_size
        #: convolution weights, shape (n_gates, window * input_size, hidden_size): gates in
        #: order z, f, o, i; rows ``j * input_size + feature``, ``j = 0`` the oldest input
        self.weight = nn.Parameter(torch.empty(pooling.n_gates, n_in, self.hidden_size))
        #: convolution biases, shape (n_gates, 1, hidden_size)
        self.bias = nn.Parameter(torch.empty(pooling.n_gates, 1, self.hidden_size))
        bound = 1.0 / n_in**0.5  # as torch.nn.Linear / Conv1d
        nn.init.uniform_(self.weight, -bound, bound)
        nn.init.uniform_(self.bias, -bound, bound)

    def extra_repr(self) -> str:
        return (f"{self.input_size}, {self.hidden_size}, window={self.window}, "
                f"pooling={self.pooling!r}, zoneout={self.zoneout}")

    def _check_x(self, x: Tensor) -> None:
        if x.dim() != 3 or x.shape[-1] != self.input_size:
            raise ValueError(f"x must have shape (batch, time, {self.input_size}); got "
                             f"{tuple(x.shape)}")

    def _padded(self, x: Tensor, past: Tensor | None) -> Tensor:
        """``x`` preceded by ``window - 1`` earlier inputs (zeros when ``past`` is None).

        Returned time-major: shape (window - 1 + time, batch, input_size), contiguous.
        """
        k1 = self.window - 1
        if past is None:
            past = x.new_zeros(k1, x.shape[0], self.input_size)
        elif past.shape != (x.shape[0], k1, self.input_size):
            raise ValueError(f"past must have shape (batch, window - 1, input_size) = "
                             f"{(x.shape[0], k1, self.input_size)}; got {tuple(past.shape)}")
        else:
            past = past.transpose(0, 1)
        return torch.cat([past, x.transpose(0, 1)], dim=0)

    def gates(self, x: Tensor, *, past: Tensor | None = None) -> tuple[Tensor, Tensor,
                                                                       tuple[Tensor, ...]]:
        """Activated gates ``z``, ``f`` (zoneout applied) and the extra gates ``(o, i)``.

        Parameters
        ----------
        x : Tensor, shape (batch, time, input_size)
            Inputs.
        past : Tensor, shape (batch, window - 1, input_size), optional
            Inputs just before ``x`` (zeros when None).

        Returns
        -------
        z, f : Tensor, shape (batch, time, hidden_size)
        extra : tuple of Tensor, each shape (batch, time, hidden_size)
        """
        self._check_x(x)
        n_batch, n_time = x.shape[:2]
        n_gates, n_hidden = self.pooling.n_gates, self.hidden_size
        xp = self._padded(x, past)  # time-major
        shifted = (xp if self.window == 1 else
                   torch.cat([xp[j:j + n_time] for j in range(self.window)], dim=-1))
        # one matrix product (time * batch, window * input) x (window * input, gates * hidden):
        # rows time-major, every row holds the gates z, f, o, i side by side; the gates are
        # handed on as (batch, time, hidden) views of it (element-wise ops and the scan keep
        # them). One GEMM, not a batched product of the input expanded per gate: its backward
        # is one GEMM per operand too (no per-gate input gradients summed afterwards).
        weight = self.weight.transpose(0, 1).reshape(self.window * self.input_size,
                                                     n_gates * n_hidden)
        pre = torch.addmm(self.bias.view(n_gates * n_hidden),
                          shifted.view(n_time * n_batch, weight.shape[0]), weight)
        # split / unbind, not indexing: their backward concatenates the gate gradients
        # (indexing would zero-fill a full-size gradient per gate); one sigmoid for all gates
        pre_z, pre_s = pre.view(n_time, n_batch, n_gates * n_hidden).split(
            [n_hidden, (n_gates - 1) * n_hidden], dim=-1)
        # tanh(x) = 2 sigmoid(2 x) - 1: this CPU build's tanh costs ~0.66 ms on 64^3 elements,
        # sigmoid ~0.11 ms and a multiply ~0.02 ms (measured, 1 thread): ~9 % of a training
        # step of the shipped network (benchmarks/bench_qrnn_speed.py)
        z = (2.0 * torch.sigmoid(2.0 * pre_z) - 1.0).transpose(0, 1)
        sig = torch.sigmoid(pre_s).view(n_time, n_batch, n_gates - 1, n_hidden).transpose(
            0, 1).unbind(2)
        f = sig[0]
        if self.zoneout > 0.0:
            if self.training:
                keep = torch.empty_like(f).bernoulli_(1.0 - self.zoneout)
                f = 1.0 - (1.0 - f) * keep
            else:
                f = 1.0 - (1.0 - f) * (1.0 - self.zoneout)
        return z, f, tuple(sig[1:])

    def forward(self, x: Tensor, c0: Tensor | None = None, *,
                past: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Run the layer over a sequence.

        Parameters
        ----------
        x : Tensor, shape (batch, time, input_size)
            Inputs.
        c0 : Tensor, shape (batch, hidden_size), optional
            Initial cell state (zeros when None).
        past : Tensor, shape (batch, window - 1, input_size), optional
            Inputs just before ``x`` for streaming (zeros when None).

        Returns
        -------
        h : Tensor, shape (batch, time, hidden_size)
            Hidden outputs.
        c_last : Tensor, shape (batch, hidden_size)
            Cell state after the last step (``c0`` or zeros for an empty sequence).
        """
        z, f, extra = self.gates(x, past=past)
        h, c = self.pooling(z, f, extra, c0)
        if x.shape[1] == 0:
            c_last = c0 if c0 is not None else x.new_zeros(x.shape[0], self.hidden_size)
        else:
            c_last = c[:, -1]
        return h, c_last


class QRNNCarry(NamedTuple):
    """What `QRNN.stream` carries from one piece of a sequence to the next.

    Attributes
    ----------
    c : Tensor, shape (num_layers, batch, hidden_size)
        Cell states after the last step.
    past : tuple of Tensor, shape (batch, window - 1, input size of the layer) each
        Last ``window - 1`` inputs of every layer.
    """

    c: Tensor
    past: tuple[Tensor, ...]


@typing.final
class QRNN(nn.Module):
    """Stack of `QRNNLayer` (batch-first), dropout between layers.

    Parameters
    ----------
    input_size : int
        Number of input features ``>= 1``.
    hidden_size : int
        Hidden units per layer ``>= 1``.
    num_layers : int
        Number of stacked layers ``>= 1``.
    window : int
        Convolution width ``>= 1`` of the first layer (and of every layer when
        ``upper_window`` is None).
    upper_window : int, optional
        Convolution width ``>= 1`` of layers 2, 3, ...; None: ``window``. ``1`` halves the
        arithmetic of those layers (window 2 then 1 is the choice of Merity, Keskar, Socher
        2018, awd-lstm-lm): the first layer already mixes neighbouring samples.
    pooling : AbstractPooling
        Pooling of every layer (`FOPooling` by default).
    zoneout : float
        Zoneout probability on ``F`` in [0, 1).
    dropout : float
        Dropout probability on the outputs of every layer but the last, in [0, 1).
    """

    def __init__(self, input_size: int, hidden_size: int, *, num_layers: int = 1,
                 window: int = 2, upper_window: int | None = None,
                 pooling: AbstractPooling | None = None,
                 zoneout: float = 0.0, dropout: float = 0.0) -> None:
        super().__init__()
        self.input_size = _check_int("input_size", input_size, 1)
        self.hidden_size = _check_int("hidden_size", hidden_size, 1)
        self.num_layers = _check_int("num_layers", num_layers, 1)
        self.dropout = _check_prob("dropout", dropout)
        self.layers = nn.ModuleList(
            QRNNLayer(input_size if k == 0 else hidden_size, hidden_size,
                      window=window if k == 0 or upper_window is None else upper_window,
                      pooling=pooling, zoneout=zoneout)
            for k in range(self.num_layers))
        self.drop = nn.Dropout(self.dropout)

    def _run(self, x: Tensor, state: Tensor | None, past: tuple[Tensor, ...] | None,
             *, tails: bool) -> tuple[Tensor, Tensor, tuple[Tensor, ...]]:
        if state is not None and state.shape != (self.num_layers, x.shape[0], self.hidden_size):
            raise ValueError(f"state must have shape (num_layers, batch, hidden_size) = "
                             f"{(self.num_layers, x.shape[0], self.hidden_size)}; got "
                             f"{tuple(state.shape)}")
        if past is not None and len(past) != self.num_layers:
            raise ValueError(f"carry.past must hold num_layers = {self.num_layers} tensors; "
                             f"got {len(past)}")
        finals, last_inputs = [], []
        h = x
        for k, layer in enumerate(self.layers):
            if k > 0:
                h = self.drop(h)
            h_in = h
            past_k = None if past is None else past[k]
            h, c_last = layer(h_in, None if state is None else state[k], past=past_k)
            finals.append(c_last)
            if tails:
                padded = layer._padded(h_in, past_k)
                tail = padded[padded.shape[0] - (layer.window - 1):]
                last_inputs.append(tail.transpose(0, 1))
        return h, torch.stack(finals), tuple(last_inputs)

    def forward(self, x: Tensor, state: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Run the stack over a sequence (zero inputs before ``t = 0``).

        Parameters
        ----------
        x : Tensor, shape (batch, time, input_size)
            Inputs.
        state : Tensor, shape (num_layers, batch, hidden_size), optional
            Initial cell states (zeros when None).

        Returns
        -------
        h : Tensor, shape (batch, time, hidden_size)
            Hidden outputs of the last layer.
        state : Tensor, shape (num_layers, batch, hidden_size)
            Cell states after the last step.
        """
        h, c, _ = self._run(x, state, None, tails=False)
        return h, c

    def stream(self, x: Tensor, carry: QRNNCarry | None = None) -> tuple[Tensor, QRNNCarry]:
        """Run the stack on the next piece of a long sequence.

        Parameters
        ----------
        x : Tensor, shape (batch, time, input_size)
            The next inputs.
        carry : QRNNCarry, optional
            What the previous call returned (None at the start of the sequence).

        Returns
        -------
        h : Tensor, shape (batch, time, hidden_size)
            Hidden outputs of the last layer.
        carry : QRNNCarry
            State to pass with the next piece.
        """
        h, c, tails = self._run(x, None if carry is None else carry.c,
                                None if carry is None else carry.past, tails=True)
        return h, QRNNCarry(c, tails)
