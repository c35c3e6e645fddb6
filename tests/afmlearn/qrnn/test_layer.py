"""QRNN layer and stack: causal convolution, pooling closed forms, zoneout, streaming."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from afmlearn.qrnn.layer import QRNN, FOPooling, FPooling, IFOPooling, QRNNLayer
from afmlearn.qrnn.scan import ChunkedScan, ReferenceScan

D = torch.float64
POOLINGS = [FPooling, FOPooling, IFOPooling]


def _x(n_batch: int, n_time: int, n_in: int, seed: int = 0) -> torch.Tensor:
    return torch.randn(n_batch, n_time, n_in, generator=torch.Generator().manual_seed(seed),
                       dtype=D)


def _constant_gates(layer: QRNNLayer, values: list[float]) -> None:
    """Zero weights, biases so that the activated gates equal ``values`` (z, f, o, i)."""
    hsz = layer.hidden_size
    with torch.no_grad():
        layer.weight.zero_()
        bias = [math.atanh(values[0])] + [math.log(v / (1 - v)) for v in values[1:]]
        layer.bias.copy_(torch.tensor(bias, dtype=D)[:, None, None].expand(-1, 1, hsz))


@pytest.mark.parametrize("window", [2, 3, 5])
def test_gates_equal_left_padded_conv1d(window: int) -> None:
    torch.manual_seed(0)
    layer = QRNNLayer(3, 4, window=window, pooling=IFOPooling()).double()
    x = _x(2, 17, 3)
    z, f, (o, i) = layer.gates(x)
    # the same masked convolution with torch's conv1d: weight (out, in, window)
    w = layer.weight.reshape(4, window, 3, 4).permute(0, 3, 2, 1).reshape(16, 3, window)
    pre = F.conv1d(F.pad(x.transpose(1, 2), (window - 1, 0)), w, layer.bias.reshape(16))
    pre = pre.transpose(1, 2).chunk(4, dim=-1)
    torch.testing.assert_close(z, torch.tanh(pre[0]))
    torch.testing.assert_close(f, torch.sigmoid(pre[1]))
    torch.testing.assert_close(o, torch.sigmoid(pre[2]))
    torch.testing.assert_close(i, torch.sigmoid(pre[3]))


@pytest.mark.parametrize("pooling", POOLINGS)
def test_causal(pooling) -> None:
    torch.manual_seed(1)
    layer = QRNNLayer(2, 5, window=3, pooling=pooling()).double()
    x = _x(2, 30, 2)
    h, _ = layer(x)
    x2 = x.clone()
    x2[:, 20:] += 1.0
    h2, _ = layer(x2)
    torch.testing.assert_close(h2[:, :20], h[:, :20], rtol=0, atol=0)
    assert (h2[:, 20] - h[:, 20]).abs().max() > 1e-6


@pytest.mark.parametrize("pooling", POOLINGS)
def test_fast_scan_equals_reference_loop_forward_backward(pooling) -> None:
    torch.manual_seed(2)
    fast = QRNNLayer(3, 6, window=2, pooling=pooling(scan=ChunkedScan(chunk=4))).double()
    slow = QRNNLayer(3, 6, window=2, pooling=pooling(scan=ReferenceScan())).double()
    slow.load_state_dict(fast.state_dict())
    x = _x(2, 41, 3)
    c0 = torch.randn(2, 6, dtype=D)
    outs = []
    for layer in (fast, slow):
        h, c = layer(x, c0)
        (h.square().sum() + c.sum()).backward()
        outs.append([h, c] + [p.grad for p in layer.parameters()])
    for a, b in zip(*outs, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)


def test_constant_gates_closed_forms() -> None:
    """Constant gates: c_t = z (1 - f^t) (f/fo, c0 = 0), c_t = i z (1 - f^t) / (1 - f) (ifo)."""
    zv, fv, ov, iv = 0.6, 0.9, 0.7, 0.4
    t = torch.arange(1, 51, dtype=D)[None, :, None]
    x = _x(2, 50, 3)
    for pooling, exact in [(FPooling(), zv * (1 - fv**t)),
                           (FOPooling(), ov * zv * (1 - fv**t)),
                           (IFOPooling(), ov * iv * zv * (1 - fv**t) / (1 - fv))]:
        layer = QRNNLayer(3, 4, pooling=pooling).double()
        _constant_gates(layer, [zv, fv, ov, iv][:pooling.n_gates])
        h, c = layer(x)
        torch.testing.assert_close(h, exact.expand(2, 50, 4))
        torch.testing.assert_close(c, h[:, -1] / (1 if isinstance(pooling, FPooling) else ov))


def test_zoneout_eval_uses_expectation() -> None:
    """Evaluation: 1 - f is scaled by 1 - zoneout, so c_t = z (1 - f_eff^t)."""
    zv, fv, p = 0.5, 0.8, 0.25
    layer = QRNNLayer(1, 3, pooling=FPooling(), zoneout=p).double().eval()
    _constant_gates(layer, [zv, fv])
    h, _ = layer(_x(1, 30, 1))
    f_eff = 1 - (1 - fv) * (1 - p)
    t = torch.arange(1, 31, dtype=D)[None, :, None]
    torch.testing.assert_close(h, (zv * (1 - f_eff**t)).expand(1, 30, 3))


def test_zoneout_training_keeps_state_for_a_fraction_p() -> None:
    torch.manual_seed(3)
    p = 0.3
    layer = QRNNLayer(2, 200, zoneout=p).double().train()
    _, f, _ = layer.gates(_x(4, 250, 2))
    zoned = (f == 1.0).double().mean().item()  # sigmoid never gives exactly 1 here
    assert abs(zoned - p) < 0.01
    layer.eval()
    _, f_eval, _ = layer.gates(_x(4, 250, 2))
    assert (f_eval < 1.0).all()
    # zoneout 0: training and evaluation agree
    plain = QRNNLayer(2, 5).double()
    x = _x(1, 9, 2)
    torch.testing.assert_close(plain.train()(x)[0], plain.eval()(x)[0])


def test_stack_composes_layers_and_dropout_only_between() -> None:
    torch.manual_seed(4)
    net = QRNN(2, 5, num_layers=3, window=3).double()
    x = _x(2, 20, 2)
    state = torch.randn(3, 2, 5, dtype=D)
    h, c = net(x, state)
    hh = x
    for k, layer in enumerate(net.layers):
        hh, ck = layer(hh, state[k])
        torch.testing.assert_close(c[k], ck)
    torch.testing.assert_close(h, hh)
    assert h.shape == (2, 20, 5) and c.shape == (3, 2, 5)


@pytest.mark.parametrize("upper", [None, 1])
@pytest.mark.parametrize("pieces", [[40], [1, 1, 5, 33], [13, 27]])
def test_stream_in_pieces_equals_one_call(pieces: list[int], upper: int | None) -> None:
    torch.manual_seed(5)
    net = QRNN(3, 4, num_layers=2, window=3, upper_window=upper, zoneout=0.2,
               dropout=0.3).double().eval()
    x = _x(2, 40, 3)
    whole, c_whole = net(x)
    carry, outs, t0 = None, [], 0
    for n in pieces:
        h, carry = net.stream(x[:, t0:t0 + n], carry)
        outs.append(h)
        t0 += n
    torch.testing.assert_close(torch.cat(outs, dim=1), whole)
    torch.testing.assert_close(carry.c, c_whole)


def test_window_one_is_a_time_distributed_projection() -> None:
    """Upper layers with window 1 (Merity et al.): gates from the current input only."""
    torch.manual_seed(7)
    layer = QRNNLayer(3, 4, window=1, pooling=IFOPooling()).double()
    x = _x(2, 11, 3)
    z, f, (o, i) = layer.gates(x)
    pre = torch.einsum("btk,gkh->gbth", x, layer.weight) + layer.bias.unsqueeze(1)
    torch.testing.assert_close(z, torch.tanh(pre[0]))
    torch.testing.assert_close(f, torch.sigmoid(pre[1]))
    torch.testing.assert_close(o, torch.sigmoid(pre[2]))
    torch.testing.assert_close(i, torch.sigmoid(pre[3]))
    net = QRNN(3, 4, num_layers=3, window=2, upper_window=1)
    assert [lay.window for lay in net.layers] == [2, 1, 1]


def test_gradients_reach_every_parameter() -> None:
    torch.manual_seed(6)
    net = QRNN(2, 4, num_layers=2, pooling=IFOPooling())
    h, _ = net(torch.randn(3, 10, 2))
    h.sum().backward()
    for name, prm in net.named_parameters():
        assert prm.grad is not None and prm.grad.abs().sum() > 0, name


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"window": 0}, "window"), ({"zoneout": 1.0}, "zoneout"),
    ({"zoneout": -0.1}, "zoneout"), ({"pooling": "fo"}, "pooling")])
def test_layer_bad_settings(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        QRNNLayer(2, 3, **kwargs)


def test_stack_bad_settings_and_inputs() -> None:
    with pytest.raises(ValueError, match="num_layers"):
        QRNN(2, 3, num_layers=0)
    with pytest.raises(ValueError, match="dropout"):
        QRNN(2, 3, dropout=1.5)
    with pytest.raises(ValueError, match="hidden_size"):
        QRNN(2, 0)
    net = QRNN(2, 3, num_layers=2)
    with pytest.raises(ValueError, match="x must have shape"):
        net(torch.zeros(1, 5, 3))
    with pytest.raises(ValueError, match="state"):
        net(torch.zeros(1, 5, 2), torch.zeros(1, 1, 3))
    with pytest.raises(ValueError, match="past"):
        net.layers[0](torch.zeros(1, 5, 2), past=torch.zeros(1, 2, 2))


def test_empty_sequence_keeps_state() -> None:
    net = QRNN(2, 3, num_layers=2).double()
    state = torch.randn(2, 4, 3, dtype=D)
    h, c = net(torch.zeros(4, 0, 2, dtype=D), state)
    assert h.shape == (4, 0, 3)
    torch.testing.assert_close(c, state)
