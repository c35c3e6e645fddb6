"""The QRNN recurrence: a reference loop and fast, numerically safe scans.

Every QRNN pooling is the element-wise linear recurrence

    c_t = a_t * c_{t-1} + b_t,        t = 1 .. T,   c_0 given (zeros by default),

with ``a_t in [0, 1]``: fo-pooling (Bradbury et al. 2016, physics.md section 6) is
``a = f``, ``b = (1 - f) * z``; ifo-pooling is ``a = f``, ``b = i * z``.

Gate convention
---------------
``f`` is the paper's forget gate: ``c_t = f_t * c_{t-1} + (1 - f_t) * z_t``, so ``f`` near 1
*remembers* and ``f`` near 0 overwrites. (The old CUDA implementation of Salesforce passes
``1 - f`` to its kernel; do not mix the two.)

Fast scans
----------
None of them forms ratios, logarithms or exponentials of gates, so all are safe for any
product of gates, including gates exactly 0 or 1: only products of values in ``[0, 1]`` (which
only shrink; underflow to 0 is the right answer) and sums of ``b`` weighted by them occur, the
same terms as in the loop, summed in another order. No clamp is needed and no error bound
beyond rounding applies.

- Plain loop (``chunk = 1``): ``T`` steps over one ``(batch, hidden)`` block each; fewest
  passes over memory, so fastest when a step is wide (training batches).
- Recursive doubling (`prefix_scan`, Hillis-Steele / Kogge-Stone): after the level with shift
  ``d`` every ``c_t`` is the state started from zero ``2 d`` steps earlier and ``A_t`` the
  product of those gates; a level is ``c_t += A_t c_{t-d}``, ``A_t *= A_{t-d}`` over the whole
  sequence at once (two operations on zero / one padded buffers), ``ceil(log2 T)`` levels, ``c_0``
  folded into ``b_1``. About ``2 log2 T`` tensor operations instead of ``T``: fastest when a
  step is narrow and the per-operation cost dominates (inference on one trace).
- Chunked (``chunk = L >= 2``): local scans of all chunks at once (``L - 1`` steps), the same
  recurrence on the chunk ends (recursive), ``c = local + cumprod(a) * c_entering``.

``chunk=None`` (default) picks per call: the loop when ``batch * hidden >= LOOP_ABOVE``, else
doubling (measured by ``benchmarks/bench_qrnn_speed.py``). A closed form inside chunks,
``c_t = sum_{s<=t} exp(S_t - S_s) b_s`` with ``S = cumsum(log a)`` (one (L x L) weight matrix per
chunk and element), was measured too and rejected: on this CPU it was 2-5x slower than
doubling at batch 1 and 5-50x slower than the loop at batch 64 (``T * L`` exponentials per
element instead of ``2 log2 T`` multiply-adds), and it needs ``a`` clamped away from 0.

Gradients are not taken through these steps: a custom `torch.autograd.Function` runs the
adjoint recurrence (the same scan backwards in time, by the same method),
``d_t = g_t + a_{t+1} d_{t+1}``, ``dL/db_t = d_t``, ``dL/da_t = d_t c_{t-1}``,
``dL/dc_0 = a_1 d_1``, so backward costs about one more scan and stores only ``c`` (the
backward is itself differentiable: double backward works). Without gradients (``eval()``
under `torch.inference_mode`) the kernel is called directly, without autograd bookkeeping.

Internally the scan runs time-major (every step touches one contiguous ``(batch, hidden)``
block); the result is returned as a ``(batch, time, hidden)`` view of time-major storage, so
inputs that are themselves such views (as in `afmlearn.qrnn.layer`) are never copied.

All arrays are batch-first: ``(batch, time, hidden)``; dimensionless.
"""

from __future__ import annotations

import abc
import math
import typing

import torch
from torch import Tensor

__all__ = [
    "AbstractScan",
    "ChunkedScan",
    "DoublingScan",
    "LOOP_ABOVE",
    "ReferenceScan",
    "auto_chunk",
    "fo_pool",
    "fo_pool_reference",
    "linear_scan",
    "linear_scan_reference",
    "prefix_scan",
]

#: below this many elements per time step (batch * hidden) the per-step Python/dispatch cost
#: dominates and recursive doubling wins; above it the plain time-major loop (``chunk = 1``)
#: does fewer passes over memory and is faster (measured on the 2-core CPU, see
#: docs/benchmarks.md, section qrnn_speed)
LOOP_ABOVE = 4096


def auto_chunk(n_time: int, n_elements: int) -> int:
    """A chunk length for the chunked scan: 1 (plain loop) for wide steps, else ~sqrt(T).

    (``chunk=None`` no longer uses it: narrow steps go to recursive doubling.)

    Parameters
    ----------
    n_time : int
        Sequence length ``T``.
    n_elements : int
        Elements per time step, ``batch * hidden``.
    """
    if n_elements >= LOOP_ABOVE:
        return 1
    return max(2, round(math.sqrt(max(n_time, 1))))


def _check(a: Tensor, b: Tensor, c0: Tensor | None) -> Tensor:
    """Validate shapes and return ``c0`` (zeros when None), shape (batch, hidden)."""
    if a.dim() != 3 or a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape (batch, time, hidden); got "
                         f"{tuple(a.shape)} and {tuple(b.shape)}")
    n_batch, _, n_hidden = a.shape
    if c0 is None:
        return a.new_zeros(n_batch, n_hidden)
    if c0.shape != (n_batch, n_hidden):
        raise ValueError(f"c0 must have shape (batch, hidden) = {(n_batch, n_hidden)}; got "
                         f"{tuple(c0.shape)}")
    return c0


def linear_scan_reference(a: Tensor, b: Tensor, c0: Tensor | None = None) -> Tensor:
    """Readable reference loop for ``c_t = a_t * c_{t-1} + b_t`` (autograd through the loop).

    Parameters
    ----------
    a : Tensor, shape (batch, time, hidden)
        Multiplier of the previous state (the forget gate ``f``), values in [0, 1].
    b : Tensor, shape (batch, time, hidden)
        Input term (``(1 - f) * z`` for fo-pooling).
    c0 : Tensor, shape (batch, hidden), optional
        State before the first step; zeros when None.

    Returns
    -------
    c : Tensor, shape (batch, time, hidden)
        States ``c_1 .. c_T``.
    """
    c = _check(a, b, c0)
    out = []
    for t in range(a.shape[1]):
        c = a[:, t] * c + b[:, t]
        out.append(c)
    return torch.stack(out, dim=1)


def fo_pool_reference(f: Tensor, z: Tensor, c0: Tensor | None = None) -> Tensor:
    """Reference fo-pooling ``c_t = f_t * c_{t-1} + (1 - f_t) * z_t`` as a plain loop.

    Parameters
    ----------
    f : Tensor, shape (batch, time, hidden)
        Forget gate in [0, 1] (paper's convention: 1 = remember).
    z : Tensor, shape (batch, time, hidden)
        Candidate values.
    c0 : Tensor, shape (batch, hidden), optional
        Initial cell state; zeros when None.

    Returns
    -------
    c : Tensor, shape (batch, time, hidden)
        Cell states ``c_1 .. c_T``.
    """
    c = _check(f, z, c0)
    out = []
    for t in range(f.shape[1]):
        c = f[:, t] * c + (1.0 - f[:, t]) * z[:, t]
        out.append(c)
    return torch.stack(out, dim=1)


def _loop(a: Tensor, b: Tensor, c0: Tensor) -> Tensor:
    """Sequential kernel (no autograd), time-major contiguous (time, batch, hidden)."""
    out = torch.empty_like(b)
    c = c0
    # views unbound once (in C++), not indexed per step: a third less time per step at
    # (64, 64) blocks (measured), where the per-step dispatch dominates
    for a_t, b_t, o_t in zip(a.unbind(0), b.unbind(0), out.unbind(0), strict=True):
        c = torch.addcmul(b_t, a_t, c, out=o_t)
    return out


def _adjoint_loop(a: Tensor, g: Tensor) -> Tensor:
    """``d_t = g_t + a_{t+1} d_{t+1}`` backwards in time (no autograd), time-major."""
    d = torch.empty_like(g)
    n_time = a.shape[0]
    d[n_time - 1] = g[n_time - 1]
    a_l, g_l, d_l = a.unbind(0), g.unbind(0), d.unbind(0)
    for t in range(n_time - 2, -1, -1):
        torch.addcmul(g_l[t], a_l[t + 1], d_l[t + 1], out=d_l[t])
    return d


def _doubling(a: Tensor, b: Tensor, c0: Tensor) -> Tensor:
    """Doubling (Hillis-Steele) kernel (no autograd), time-major (time, batch, hidden).

    After the level with shift ``d``, ``c[t]`` holds the state at ``t`` started from zero
    ``2 d`` steps earlier and ``A[t]`` the product of those ``2 d`` gates; levels
    ``d = 1, 2, 4, ...`` until ``d >= T``. Both buffers are preceded by ``pad`` rows of zeros
    (``c``) and ones (``A``), so a level is two whole-array operations, with no special case
    for ``t < d``; the two buffer pairs alternate (a level may not overwrite what it reads).
    """
    n_time = a.shape[0]
    if n_time <= 2:
        return _loop(a, b, c0)
    pad = 1 << ((n_time - 1).bit_length() - 1)  # the largest shift d < T
    spec = (0, 0) * (a.dim() - 1) + (pad, 0)
    c = torch.nn.functional.pad(b, spec)
    c[pad].addcmul_(a[0], c0)  # fold c0 into b_1: c_1 = a_1 c0 + b_1
    c_next = torch.zeros_like(c)
    prod = torch.nn.functional.pad(a, spec, value=1.0)
    prod_next = torch.ones_like(prod)
    d = 1
    while d < n_time:
        torch.addcmul(c[pad:], prod[pad:], c[pad - d:pad - d + n_time], out=c_next[pad:])
        c, c_next = c_next, c
        if 2 * d < n_time:  # the last level's products are not needed
            torch.mul(prod[pad:], prod[pad - d:pad - d + n_time], out=prod_next[pad:])
            prod, prod_next = prod_next, prod
        d *= 2
    return c[pad:]


def _kernel(a: Tensor, b: Tensor, c0: Tensor, chunk: int) -> Tensor:
    """Kernel (no autograd), time-major (time, batch, hidden): ``chunk = 0`` doubling, else
    chunked (``1``: plain loop); see module docstring."""
    n_time = a.shape[0]
    if chunk == 0:
        return _doubling(a, b, c0)
    if n_time <= chunk or chunk < 2:
        return _loop(a, b, c0)
    n = -(-n_time // chunk)
    pad = n * chunk - n_time
    if pad:  # a = 1, b = 0 after the end: keeps the state, does not touch earlier outputs
        a = torch.cat([a, a.new_ones(pad, *a.shape[1:])])
        b = torch.cat([b, b.new_zeros(pad, *b.shape[1:])])
    a4 = a.reshape(n, chunk, *a.shape[1:])
    loc = b.reshape(n, chunk, *b.shape[1:]).clone()
    for t in range(1, chunk):  # local scans of all chunks at once, zero entering state
        loc[:, t].addcmul_(a4[:, t], loc[:, t - 1])
    prod = torch.cumprod(a4, dim=1)  # in [0, 1]: products only shrink
    # state at the end of every chunk: the same recurrence on the chunk ends
    ends = _kernel(prod[:, -1].contiguous(), loc[:, -1].contiguous(), c0, chunk)  # (n, B, H)
    entering = torch.cat([c0.unsqueeze(0), ends[:-1]])
    c = loc.addcmul_(prod, entering.unsqueeze(1)).reshape(n * chunk, *b.shape[1:])
    return c[:n_time] if pad else c


def _time_major(x: Tensor) -> Tensor:
    """(batch, time, hidden) -> (time, batch, hidden) with unit stride along hidden.

    Free for time-major storage, also when the rows hold other data too (the gates of
    `afmlearn.qrnn.layer` are column blocks of one matrix); otherwise a copy.
    """
    t = x.transpose(0, 1)
    return t if t.stride(-1) == 1 else t.contiguous()


class _LinearScan(torch.autograd.Function):
    """``c_t = a_t c_{t-1} + b_t`` with the adjoint recurrence as backward (time-major)."""

    @staticmethod
    def forward(ctx, a: Tensor, b: Tensor, c0: Tensor, chunk: int) -> Tensor:
        c = _kernel(a, b, c0.contiguous(), chunk)
        ctx.save_for_backward(a, c, c0)
        ctx.chunk = chunk
        return c

    @staticmethod
    def backward(ctx, g: Tensor):
        a, c, c0 = ctx.saved_tensors
        grad_a = grad_c0 = None
        if torch.is_grad_enabled() or ctx.chunk == 0 or a.shape[0] > ctx.chunk > 1:
            # adjoint d_t = g_t + a_{t+1} d_{t+1}: the same scan on the time-reversed sequence
            # (through `apply` again, so that double backward works too)
            a_next = torch.cat([a[1:], a.new_zeros(1, *a.shape[1:])])
            d = _LinearScan.apply(a_next.flip(0), g.flip(0), torch.zeros_like(c0),
                                  ctx.chunk).flip(0)
            if ctx.needs_input_grad[0]:
                grad_a = d * torch.cat([c0.unsqueeze(0), c[:-1]])
        else:  # plain loop backwards, no copies (first-order gradients only)
            d = _adjoint_loop(a, g.contiguous())
            if ctx.needs_input_grad[0]:
                grad_a = torch.empty_like(d)
                torch.mul(d[0], c0, out=grad_a[0])
                torch.mul(d[1:], c[:-1], out=grad_a[1:])
        if ctx.needs_input_grad[2]:
            grad_c0 = a[0] * d[0]
        return grad_a, d, grad_c0, None


def _check_chunk(chunk: int) -> int:
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk must be an integer >= 1; got {chunk!r}")
    return chunk


def linear_scan(a: Tensor, b: Tensor, c0: Tensor | None = None, *,
                chunk: int | None = None) -> Tensor:
    """Fast solution of ``c_t = a_t * c_{t-1} + b_t`` (differentiable).

    Parameters
    ----------
    a : Tensor, shape (batch, time, hidden)
        Multiplier of the previous state, values in [0, 1] (the forget gate ``f``).
    b : Tensor, shape (batch, time, hidden)
        Input term.
    c0 : Tensor, shape (batch, hidden), optional
        State before the first step; zeros when None.
    chunk : int, optional
        Chunk length ``L >= 1`` (``1`` or ``L >= time``: plain sequential loop); None (default)
        chooses per call: the plain loop for wide steps (``batch * hidden >= LOOP_ABOVE``),
        else recursive doubling (`prefix_scan`). Results do not depend on it beyond
        rounding; speed does.

    Returns
    -------
    c : Tensor, shape (batch, time, hidden)
        States ``c_1 .. c_T``.
    """
    c0 = _check(a, b, c0)
    if chunk is None:
        chunk = 1 if a.shape[0] * a.shape[2] >= LOOP_ABOVE else 0
    else:
        _check_chunk(chunk)
    return _run(a, b, c0, chunk)


def _run(a: Tensor, b: Tensor, c0: Tensor, chunk: int) -> Tensor:
    """Dispatch to the kernel (``chunk = 0``: doubling), through autograd only if needed."""
    if a.shape[1] == 0:
        return b.clone()
    if a.dtype != b.dtype or c0.dtype != b.dtype:
        raise ValueError(f"a, b and c0 must share one dtype; got {a.dtype}, {b.dtype}, "
                         f"{c0.dtype}")
    if torch.is_grad_enabled() and (a.requires_grad or b.requires_grad or c0.requires_grad):
        return _LinearScan.apply(_time_major(a), _time_major(b), c0, chunk).transpose(0, 1)
    return _kernel(_time_major(a), _time_major(b), c0.contiguous(), chunk).transpose(0, 1)


def prefix_scan(a: Tensor, b: Tensor, c0: Tensor | None = None) -> Tensor:
    """Solution of ``c_t = a_t * c_{t-1} + b_t`` by recursive doubling (differentiable).

    ``ceil(log2 T)`` whole-sequence steps (see module docstring); fastest when a time step is
    narrow (``batch * hidden`` small, e.g. inference on one trace).

    Parameters
    ----------
    a : Tensor, shape (batch, time, hidden)
        Multiplier of the previous state, values in [0, 1] (the forget gate ``f``).
    b : Tensor, shape (batch, time, hidden)
        Input term.
    c0 : Tensor, shape (batch, hidden), optional
        State before the first step; zeros when None.

    Returns
    -------
    c : Tensor, shape (batch, time, hidden)
        States ``c_1 .. c_T``; equal to `linear_scan_reference` up to rounding.
    """
    return _run(a, b, _check(a, b, c0), 0)


def fo_pool(f: Tensor, z: Tensor, c0: Tensor | None = None, *,
            chunk: int | None = None) -> Tensor:
    """Fast fo-pooling ``c_t = f_t * c_{t-1} + (1 - f_t) * z_t`` (differentiable).

    Parameters
    ----------
    f : Tensor, shape (batch, time, hidden)
        Forget gate in [0, 1] (paper's convention: 1 = remember).
    z : Tensor, shape (batch, time, hidden)
        Candidate values.
    c0 : Tensor, shape (batch, hidden), optional
        Initial cell state; zeros when None.
    chunk : int, optional
        Chunk length of the scan, see `linear_scan` (None: loop or doubling, per call).

    Returns
    -------
    c : Tensor, shape (batch, time, hidden)
        Cell states ``c_1 .. c_T``; equal to `fo_pool_reference` up to rounding.
    """
    _check(f, z, c0)
    return linear_scan(f, (1.0 - f) * z, c0, chunk=chunk)


class AbstractScan(abc.ABC):
    """Strategy that solves ``c_t = a_t * c_{t-1} + b_t`` (used by the pooling objects)."""

    @abc.abstractmethod
    def __call__(self, a: Tensor, b: Tensor, c0: Tensor | None = None) -> Tensor:
        """States ``c``, shape (batch, time, hidden), from ``a``, ``b`` of that shape and
        ``c0`` of shape (batch, hidden) (zeros when None)."""


@typing.final
class ChunkedScan(AbstractScan):
    """The fast chunked scan `linear_scan` with a fixed chunk length.

    Parameters
    ----------
    chunk : int, optional
        Chunk length ``>= 1``; None (default) chooses per call between the plain loop and
        recursive doubling (see `linear_scan`).
    """

    def __init__(self, *, chunk: int | None = None) -> None:
        self.chunk = None if chunk is None else _check_chunk(chunk)

    def __call__(self, a: Tensor, b: Tensor, c0: Tensor | None = None) -> Tensor:
        return linear_scan(a, b, c0, chunk=self.chunk)

    def __repr__(self) -> str:
        return f"ChunkedScan(chunk={self.chunk})"


@typing.final
class DoublingScan(AbstractScan):
    """Recursive doubling `prefix_scan`, whatever the width of a step."""

    def __call__(self, a: Tensor, b: Tensor, c0: Tensor | None = None) -> Tensor:
        return prefix_scan(a, b, c0)

    def __repr__(self) -> str:
        return "DoublingScan()"


@typing.final
class ReferenceScan(AbstractScan):
    """The readable loop `linear_scan_reference` (slow; for tests and checks)."""

    def __call__(self, a: Tensor, b: Tensor, c0: Tensor | None = None) -> Tensor:
        return linear_scan_reference(a, b, c0)

    def __repr__(self) -> str:
        return "ReferenceScan()"
