"""Sequence networks: one interface for QRNN, LSTM and GRU; causal; QRNN learns a recurrence."""

from __future__ import annotations

import pytest
import torch

from afmlearn.qrnn.layer import QRNN, FPooling, IFOPooling
from afmlearn.qrnn.networks import AbstractSequenceNet, GRUNet, LSTMNet, QRNNNet

NETS = [
    lambda: QRNNNet(3, 8),
    lambda: QRNNNet(3, 8, num_layers=1, window=3, pooling=IFOPooling(), zoneout=0.1),
    lambda: LSTMNet(3, 8),
    lambda: GRUNet(3, 8, num_layers=1),
]


@pytest.mark.parametrize("make", NETS)
def test_interface_and_causality(make) -> None:
    torch.manual_seed(0)
    net = make().double().eval()
    assert isinstance(net, AbstractSequenceNet)
    assert (net.input_size, net.hidden_size) == (3, 8)
    x = torch.randn(2, 25, 3, dtype=torch.float64)
    h = net.encode(x)
    assert h.shape == (2, 25, 8)
    torch.testing.assert_close(net(x), h)
    x2 = x.clone()
    x2[:, 15:] -= 2.0
    h2 = net.encode(x2)
    torch.testing.assert_close(h2[:, :15], h[:, :15], rtol=0, atol=0)
    assert (h2[:, 15:] - h[:, 15:]).abs().max() > 1e-4
    with pytest.raises(ValueError, match="x must have shape"):
        net.encode(torch.zeros(2, 5, 4, dtype=torch.float64))


def test_qrnn_net_is_the_stack() -> None:
    torch.manual_seed(1)
    net = QRNNNet(2, 6, num_layers=2, window=2)
    ref = QRNN(2, 6, num_layers=2, window=2)
    ref.load_state_dict(net.qrnn.state_dict())
    x = torch.randn(3, 12, 2)
    torch.testing.assert_close(net.encode(x), ref(x)[0])
    assert net.num_layers == 2


def test_abstract_and_bad_settings() -> None:
    with pytest.raises(TypeError):
        AbstractSequenceNet()  # type: ignore[abstract]
    for cls in (QRNNNet, LSTMNet, GRUNet):
        with pytest.raises(ValueError, match="hidden_size"):
            cls(2, 0)
        with pytest.raises(ValueError, match="num_layers"):
            cls(2, 4, num_layers=0)
    with pytest.raises(ValueError, match="dropout"):
        LSTMNet(2, 4, dropout=1.0)


def test_qrnn_learns_exponential_smoothing() -> None:
    """Target y_t = 0.9 y_{t-1} + 0.1 x_t needs the recurrence (the conv alone sees 2 steps).

    One f-pooling unit represents it exactly (f = 0.9, z = x); a small QRNN with a linear
    read-out trained for 150 Adam steps must bring the relative mean-square error below 2 %
    (a network without memory cannot: the target depends on ~10 past steps).
    """
    torch.manual_seed(2)
    x = torch.randn(32, 60, 1)
    y = torch.zeros_like(x)
    for t in range(60):
        y[:, t] = (0.9 * y[:, t - 1] if t else 0.0) + 0.1 * x[:, t]
    net = QRNNNet(1, 8, num_layers=1, pooling=FPooling())
    head = torch.nn.Linear(8, 1)
    opt = torch.optim.Adam([*net.parameters(), *head.parameters()], lr=3e-2)

    def loss() -> torch.Tensor:
        return (head(net(x)) - y).square().mean() / y.square().mean()

    first = loss().item()
    for _ in range(150):
        opt.zero_grad()
        out = loss()
        out.backward()
        opt.step()
    assert loss().item() < 0.02 < first
