"""The fast chunked scan against the readable loop and closed forms (float64)."""

from __future__ import annotations

import pytest
import torch

from afmlearn.qrnn.scan import (
    LOOP_ABOVE,
    ChunkedScan,
    DoublingScan,
    ReferenceScan,
    auto_chunk,
    fo_pool,
    fo_pool_reference,
    linear_scan,
    linear_scan_reference,
    prefix_scan,
)

D = torch.float64


def _inputs(n_batch: int, n_time: int, n_hidden: int, *, seed: int = 0, lo: float = 0.0,
            hi: float = 1.0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    f = lo + (hi - lo) * torch.rand(n_batch, n_time, n_hidden, generator=g, dtype=D)
    z = torch.tanh(2 * torch.randn(n_batch, n_time, n_hidden, generator=g, dtype=D))
    c0 = torch.randn(n_batch, n_hidden, generator=g, dtype=D)
    return f, z, c0


@pytest.mark.parametrize("n_time", [1, 2, 7, 8, 9, 64, 65, 300])
@pytest.mark.parametrize("chunk", [1, 2, 3, 8, 16, 64])
def test_forward_matches_loop(n_time: int, chunk: int) -> None:
    f, z, c0 = _inputs(3, n_time, 5, seed=n_time * 100 + chunk)
    ref = fo_pool_reference(f, z, c0)
    torch.testing.assert_close(fo_pool(f, z, c0, chunk=chunk), ref, rtol=1e-13, atol=1e-13)
    # no c0 = zeros
    torch.testing.assert_close(fo_pool(f, z, chunk=chunk), fo_pool_reference(f, z),
                               rtol=1e-13, atol=1e-13)


def test_closed_form_constant_gates() -> None:
    """Constant f and z: c_t = z + (c0 - z) f^t."""
    n_time = 500
    f = torch.full((2, n_time, 3), 0.97, dtype=D)
    z = torch.tensor([0.3, -0.7, 0.9], dtype=D).expand(2, n_time, 3)
    c0 = torch.tensor([[1.0, 0.0, -1.0], [0.5, 0.5, 0.5]], dtype=D)
    t = torch.arange(1, n_time + 1, dtype=D)[None, :, None]
    exact = z + (c0[:, None, :] - z) * 0.97 ** t
    torch.testing.assert_close(fo_pool(f, z, c0, chunk=16), exact, rtol=1e-12, atol=1e-13)


def test_limits_remember_and_overwrite() -> None:
    f, z, c0 = _inputs(2, 100, 4)
    ones, zeros = torch.ones_like(f), torch.zeros_like(f)
    # f = 1: the state never changes; f = 0: the state is the candidate
    torch.testing.assert_close(fo_pool(ones, z, c0, chunk=8), c0[:, None].expand_as(z))
    torch.testing.assert_close(fo_pool(zeros, z, c0, chunk=8), z)


@pytest.mark.parametrize(("lo", "hi"), [(0.0, 1e-6), (1.0 - 1e-6, 1.0), (0.999, 1.0),
                                        (0.0, 1.0)])
@pytest.mark.parametrize("chunk", [1, 16])
def test_long_sequences_extreme_gates_forward_backward(lo: float, hi: float,
                                                       chunk: int) -> None:
    """Long products of forget gates near 0 and near 1: finite, equal to the loop."""
    f, z, c0 = _inputs(2, 3000, 3, seed=7, lo=lo, hi=hi)
    w = torch.randn(2, 3000, 3, dtype=D, generator=torch.Generator().manual_seed(1))

    def grads(fn):
        fr, zr, cr = (v.clone().requires_grad_(True) for v in (f, z, c0))
        c = fn(fr, zr, cr)
        (c * w).sum().backward()
        return c.detach(), fr.grad, zr.grad, cr.grad

    got = grads(lambda a, b, c: fo_pool(a, b, c, chunk=chunk))
    ref = grads(fo_pool_reference)
    for g, r in zip(got, ref, strict=True):
        assert torch.isfinite(g).all()
        torch.testing.assert_close(g, r, rtol=1e-10, atol=1e-10)


def test_underflowing_products_stay_finite() -> None:
    """A product of 10^4 gates of 1e-3 underflows to 0; nothing may become inf or NaN."""
    f = torch.full((1, 10_000, 2), 1e-3, dtype=D, requires_grad=True)
    z = torch.ones(1, 10_000, 2, dtype=D, requires_grad=True)
    c = fo_pool(f, z, torch.full((1, 2), 5.0, dtype=D), chunk=32)
    c.sum().backward()
    assert torch.isfinite(c).all() and torch.isfinite(f.grad).all()
    assert c[0, 0, 0].item() == pytest.approx(1e-3 * 5 + (1 - 1e-3))
    torch.testing.assert_close(c[:, 5:], torch.ones_like(c[:, 5:]), rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(c, fo_pool_reference(f, z, torch.full((1, 2), 5.0, dtype=D)))


@pytest.mark.parametrize("chunk", [1, 3, 4, 50])
def test_gradcheck_and_gradgradcheck(chunk: int) -> None:
    f, z, c0 = _inputs(2, 11, 3, seed=chunk)
    args = tuple(v.requires_grad_(True) for v in (f, z, c0))

    def fn(a, b, c):
        return fo_pool(a, b, c, chunk=chunk)

    assert torch.autograd.gradcheck(fn, args)
    assert torch.autograd.gradgradcheck(fn, args)


def test_linear_scan_general_b_matches_loop() -> None:
    f, z, c0 = _inputs(3, 77, 4, seed=3)
    b = 3.0 * z  # b unrelated to a (ifo-pooling)
    torch.testing.assert_close(linear_scan(f, b, c0, chunk=5), linear_scan_reference(f, b, c0),
                               rtol=1e-13, atol=1e-13)


def test_float32_long_sequence_close_to_float64_loop() -> None:
    f, z, c0 = _inputs(4, 4096, 8, seed=11, lo=0.9, hi=1.0)
    ref = fo_pool_reference(f, z, c0)
    got = fo_pool(f.float(), z.float(), c0.float(), chunk=64).double()
    torch.testing.assert_close(got, ref, rtol=0, atol=2e-5)


def test_no_gradient_for_c0_when_not_required() -> None:
    f, z, _ = _inputs(1, 10, 2)
    f.requires_grad_(True)
    c = fo_pool(f, z)
    c.sum().backward()
    assert f.grad is not None and z.grad is None


def test_strategies() -> None:
    f, z, c0 = _inputs(2, 40, 3, seed=5)
    b = (1 - f) * z
    ref = ReferenceScan()(f, b, c0)
    torch.testing.assert_close(ChunkedScan(chunk=6)(f, b, c0), ref)
    torch.testing.assert_close(ChunkedScan(chunk=None)(f, b, c0), ref)
    assert "ChunkedScan" in repr(ChunkedScan())


def test_auto_chunk_both_regimes_match_loop() -> None:
    assert auto_chunk(64, 64 * 128) == 1  # wide steps: plain loop
    assert auto_chunk(64, 128) == 8  # narrow steps: ~sqrt(T)
    assert auto_chunk(1, 1) == 2
    for shape in [(1, 300, 4), (64, 70, 80)]:
        f, z, c0 = _inputs(*shape, seed=9)
        torch.testing.assert_close(fo_pool(f, z, c0), fo_pool_reference(f, z, c0),
                                   rtol=1e-13, atol=1e-13)


def test_empty_sequence() -> None:
    f = torch.zeros(2, 0, 3, dtype=D)
    assert fo_pool(f, f).shape == (2, 0, 3)


@pytest.mark.parametrize("chunk", [0, -1, 2.5, True])
def test_bad_chunk(chunk) -> None:
    f, z, _ = _inputs(1, 4, 2)
    with pytest.raises(ValueError, match="chunk"):
        fo_pool(f, z, chunk=chunk)
    with pytest.raises(ValueError, match="chunk"):
        ChunkedScan(chunk=chunk)


def test_bad_shapes() -> None:
    f, z, c0 = _inputs(2, 5, 3)
    with pytest.raises(ValueError, match="same shape"):
        fo_pool(f, z[:, :4])
    with pytest.raises(ValueError, match="c0"):
        fo_pool(f, z, c0[:, :2])
    with pytest.raises(ValueError, match="same shape"):
        fo_pool(f[0], z[0])


# --- recursive doubling (`prefix_scan`, `DoublingScan`, the default for narrow steps) ---


def _grads(fn, a, b, c0, w):
    ar, br, cr = (v.clone().requires_grad_(True) for v in (a, b, c0))
    c = fn(ar, br, cr)
    (c * w).sum().backward()
    return c.detach(), ar.grad, br.grad, cr.grad


@pytest.mark.parametrize("n_time", [1, 2, 3, 4, 5, 7, 8, 9, 63, 64, 65, 300])
def test_doubling_forward_backward_match_loop(n_time: int) -> None:
    """T not a power of two, c0 given or not, general b; forward and all gradients."""
    f, z, c0 = _inputs(3, n_time, 5, seed=n_time)
    b = 2.0 * z
    w = torch.randn(3, n_time, 5, dtype=D, generator=torch.Generator().manual_seed(2))
    got = _grads(prefix_scan, f, b, c0, w)
    ref = _grads(linear_scan_reference, f, b, c0, w)
    for g, r in zip(got, ref, strict=True):
        torch.testing.assert_close(g, r, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(prefix_scan(f, b), linear_scan_reference(f, b),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(("lo", "hi"), [(0.0, 1e-6), (1.0 - 1e-6, 1.0), (0.999, 1.0),
                                        (0.0, 1.0)])
def test_doubling_extreme_gates_long(lo: float, hi: float) -> None:
    """Long products of gates near 0 and near 1 (3000 steps): finite, equal to the loop."""
    f, z, c0 = _inputs(2, 3000, 3, seed=8, lo=lo, hi=hi)
    b = (1 - f) * z
    w = torch.randn(2, 3000, 3, dtype=D, generator=torch.Generator().manual_seed(3))
    got = _grads(prefix_scan, f, b, c0, w)
    ref = _grads(linear_scan_reference, f, b, c0, w)
    for g, r in zip(got, ref, strict=True):
        assert torch.isfinite(g).all()
        torch.testing.assert_close(g, r, rtol=1e-10, atol=1e-10)


def test_doubling_gates_exactly_zero_and_one() -> None:
    """Gates exactly 0 and 1 (mixed): no NaN from 0 * inf or log 0, equal to the loop."""
    f, z, c0 = _inputs(2, 37, 4, seed=4)
    g = torch.Generator().manual_seed(5)
    pick = torch.randint(0, 3, f.shape, generator=g)
    f = torch.where(pick == 0, 0.0, torch.where(pick == 1, 1.0, f))
    w = torch.randn(f.shape, dtype=D, generator=g)
    got = _grads(prefix_scan, f, z, c0, w)
    ref = _grads(linear_scan_reference, f, z, c0, w)
    for a, r in zip(got, ref, strict=True):
        assert torch.isfinite(a).all()
        torch.testing.assert_close(a, r, rtol=1e-13, atol=1e-13)
    ones = torch.ones_like(f)
    torch.testing.assert_close(prefix_scan(ones, torch.zeros_like(z), c0),
                               c0[:, None].expand_as(z))
    torch.testing.assert_close(prefix_scan(torch.zeros_like(f), z, c0), z)


def test_doubling_underflow_stays_finite() -> None:
    f = torch.full((1, 10_000, 2), 1e-3, dtype=D, requires_grad=True)
    z = torch.ones(1, 10_000, 2, dtype=D, requires_grad=True)
    c0 = torch.full((1, 2), 5.0, dtype=D)
    c = prefix_scan(f, (1 - f) * z, c0)
    c.sum().backward()
    assert torch.isfinite(c).all() and torch.isfinite(f.grad).all()
    torch.testing.assert_close(c, fo_pool_reference(f, z, c0))


@pytest.mark.parametrize("n_time", [1, 5, 8, 11])
def test_doubling_gradcheck_and_gradgradcheck(n_time: int) -> None:
    f, z, c0 = _inputs(2, n_time, 3, seed=20 + n_time)
    args = tuple(v.requires_grad_(True) for v in (f, z, c0))
    assert torch.autograd.gradcheck(prefix_scan, args)
    assert torch.autograd.gradgradcheck(prefix_scan, args)


def test_doubling_float32_close_to_float64_loop() -> None:
    f, z, c0 = _inputs(4, 4096, 8, seed=12, lo=0.9, hi=1.0)
    ref = fo_pool_reference(f, z, c0)
    got = prefix_scan(f.float(), ((1 - f) * z).float(), c0.float()).double()
    torch.testing.assert_close(got, ref, rtol=0, atol=2e-5)


def test_default_picks_doubling_for_narrow_steps_and_loop_for_wide() -> None:
    """chunk=None: both regimes equal to the loop, forward and backward, and without grad."""
    for shape in [(1, 64, 16), (2, 300, 8), (64, 70, LOOP_ABOVE // 64)]:
        f, z, c0 = _inputs(*shape, seed=13)
        w = torch.randn(shape, dtype=D, generator=torch.Generator().manual_seed(4))
        got = _grads(lambda a, b, c: linear_scan(a, b, c), f, z, c0, w)
        ref = _grads(linear_scan_reference, f, z, c0, w)
        for g, r in zip(got, ref, strict=True):
            torch.testing.assert_close(g, r, rtol=1e-12, atol=1e-12)
        with torch.inference_mode():
            torch.testing.assert_close(linear_scan(f, z, c0), ref[0], rtol=1e-12, atol=1e-12)


def test_doubling_strategy_and_noncontiguous_inputs() -> None:
    f, z, c0 = _inputs(2, 40, 6, seed=6)
    ref = ReferenceScan()(f, z, c0)
    torch.testing.assert_close(DoublingScan()(f, z, c0), ref)
    assert repr(DoublingScan()) == "DoublingScan()"
    # gate blocks side by side in time-major rows (as the layer hands them on)
    wide = torch.cat([f, z], dim=-1).transpose(0, 1).contiguous().transpose(0, 1)
    fa, zb = wide.split([6, 6], dim=-1)
    for scan in (DoublingScan(), ChunkedScan(chunk=1), ChunkedScan(chunk=4)):
        torch.testing.assert_close(scan(fa, zb, c0), ref)
