"""OrbitModule and the forecast strategies: layout of the forecast, feedback of the
autoregressive rollout, loss terms, and a one-epoch fit that lowers the loss."""

from __future__ import annotations

import lightning.pytorch as pl
import pytest
import torch
from torch.nn import functional as nnf

from afmlearn.qrnn.evaluate import nrmse_per_period
from afmlearn.qrnn.forecast import AutoregressiveForecast, DirectForecast
from afmlearn.qrnn.losses import MSEOrbitLoss, PeriodNRMSELoss
from afmlearn.qrnn.module import OrbitModule
from afmlearn.qrnn.networks import GRUNet, QRNNNet

B, P, F, H = 3, 8, 3, 5


def _x() -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    x = torch.randn(B, P, F, generator=g)
    x[..., 1:] = x[:, :1, 1:]               # constant side channels, as in the data
    return x


def test_direct_forecast_puts_period_k_in_block_k():
    x = _x()
    t = torch.arange(P, dtype=torch.float32)

    def step(inp):
        out = torch.stack([100.0 * k + t for k in range(4)], dim=-1)   # (P, horizon)
        return out.expand(inp.shape[0], P, 4), torch.zeros(inp.shape[0], P, H)

    y, _ = DirectForecast().rollout(step, x, horizon=4, deflection_channel=0, base=None)
    assert y.shape == (B, 4 * P)
    for k in range(4):
        torch.testing.assert_close(y[:, k * P:(k + 1) * P], (100.0 * k + t).expand(B, P))
    y_res, _ = DirectForecast().rollout(step, x, horizon=4, deflection_channel=0,
                                        base=lambda u: u.unsqueeze(-1).expand(*u.shape, 4))
    torch.testing.assert_close(y_res - y, x[:, :, 0].repeat(1, 4), atol=1e-4, rtol=0)


def test_autoregressive_forecast_feeds_its_prediction_back():
    x = _x()
    seen = []

    def step(inp):                          # correction +1 per pass; records its inputs
        seen.append(inp.clone())
        return torch.ones(inp.shape[0], P, 1), torch.full((inp.shape[0], P, H), len(seen) * 1.0)

    y, hidden = AutoregressiveForecast().rollout(step, x, horizon=3, deflection_channel=0,
                                                  base=lambda u: u.unsqueeze(-1))
    for k in range(3):                      # period k = x + (k + 1)
        torch.testing.assert_close(y[:, k * P:(k + 1) * P], x[:, :, 0] + (k + 1))
    assert len(seen) == 3
    torch.testing.assert_close(seen[2][..., 0], x[..., 0] + 2)      # fed back
    torch.testing.assert_close(seen[2][..., 1:], x[..., 1:])        # side channels carried
    torch.testing.assert_close(hidden, torch.full((B, P, H), 1.0))  # hidden of the input period


@pytest.mark.parametrize("forecast", [DirectForecast(), AutoregressiveForecast()])
def test_module_outputs_and_loss_terms(forecast):
    torch.manual_seed(0)
    module = OrbitModule(QRNNNet(F, H, num_layers=1), horizon=3, forecast=forecast,
                         coupled_weight=0.3, sweet_weight=0.7, pos_weight=2.0,
                         harmonics=3, orbit_loss=MSEOrbitLoss())
    x = _x()
    out = module(x)
    assert out["y"].shape == (B, 3 * P) and out["logits"].shape == (B, 2)
    assert out["hidden"].shape == (B, P, H)
    batch = {"x": x, "y": torch.randn(B, 3 * P), "coupled": torch.tensor([0.0, 1.0, 1.0]),
             "sweet": torch.tensor([0.0, 0.0, 1.0])}
    terms = module.losses(batch)
    logits = module(x)["logits"]
    pw = torch.tensor(2.0)
    ref_c = nnf.binary_cross_entropy_with_logits(logits[:, 0], batch["coupled"], pos_weight=pw)
    ref_s = nnf.binary_cross_entropy_with_logits(logits[:, 1], batch["sweet"], pos_weight=pw)
    ref_o = ((module(x)["y"] - batch["y"]) ** 2).mean()
    torch.testing.assert_close(terms["bce_coupled"], ref_c)
    torch.testing.assert_close(terms["loss"], ref_o + 0.3 * ref_c + 0.7 * ref_s)
    scores = module.predict_windows(x, batch_size=2)
    assert scores["coupled"].shape == (B,) and scores["activation"].shape == (B, H)
    assert torch.all((scores["coupled"] >= 0) & (scores["coupled"] <= 1))


def test_module_rejects_bad_settings():
    net = GRUNet(F, H, num_layers=1)
    with pytest.raises(ValueError, match="horizon"):
        OrbitModule(net, horizon=0)
    with pytest.raises(ValueError, match="forecast"):
        OrbitModule(net, forecast="direct")
    with pytest.raises(ValueError, match="coupled_weight"):
        OrbitModule(net, coupled_weight=-1.0)
    with pytest.raises(ValueError, match="x must have shape"):
        OrbitModule(net)(torch.zeros(P, F))


def _mean_loss(module, loader) -> float:
    module.eval()
    with torch.no_grad():
        values = [float(module.losses(b)["loss"]) for b in loader]
    module.train()
    return sum(values) / len(values)


def test_a_short_fit_lowers_the_loss(compose_train, tmp_path):
    """Five epochs on the tiny set (series, sweeps and the sensor chain since issue 15: one
    epoch of batch 4 measured only a 19 % drop) lower the training loss by > 30 %."""
    from hydra.utils import instantiate

    cfg = compose_train(tmp_path, "data.batch_size=4")
    dm = instantiate(cfg.data)
    dm.prepare_data()
    dm.setup("fit")
    pl.seed_everything(0, workers=True)
    module = OrbitModule(QRNNNet(dm.n_features, 16), horizon=cfg.data.horizon,
                         optimizer=lambda params: torch.optim.Adam(params, lr=1e-2))
    before = _mean_loss(module, dm.train_dataloader())
    trainer = pl.Trainer(max_epochs=5, accelerator="cpu", logger=False,
                         enable_checkpointing=False, enable_progress_bar=False,
                         enable_model_summary=False, deterministic=True)
    trainer.fit(module, train_dataloaders=dm.train_dataloader())
    after = _mean_loss(module, dm.train_dataloader())
    assert after < 0.7 * before, (before, after)


def test_harmonic_pooling_reads_amplitudes_independently_of_phase():
    module = OrbitModule(GRUNet(F, 2, num_layers=1), harmonics=4)
    p = 32
    t = torch.arange(p, dtype=torch.float32) / p
    for phase in (0.0, 1.3):
        h = torch.stack([0.5 + 0.7 * torch.cos(2 * torch.pi * 3 * t + phase),
                         0.2 * torch.sin(2 * torch.pi * 1 * t + phase)], dim=-1)[None]
        feats = module.pool(h)                           # (1, (2 + 4) * 2)
        harm = feats[0, 4:].reshape(4, 2)                # |H_k| per unit, k = 1..4
        torch.testing.assert_close(feats[0, :2], torch.tensor([0.5, 0.0]), atol=1e-6, rtol=0)
        torch.testing.assert_close(harm[:, 0], torch.tensor([0.0, 0.0, 0.7, 0.0]),
                                   atol=1e-5, rtol=0)
        torch.testing.assert_close(harm[:, 1], torch.tensor([0.2, 0.0, 0.0, 0.0]),
                                   atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match="harmonics"):
        module.pool(torch.zeros(1, 6, 2))


def test_residual_module_starts_at_persistence():
    """Zero read-out: the untrained residual module repeats the input period exactly."""
    torch.manual_seed(0)
    x = _x()
    for forecast in (DirectForecast(), AutoregressiveForecast()):
        for k in (0, 2, P // 2):
            module = OrbitModule(QRNNNet(F, H, num_layers=1), horizon=3, forecast=forecast,
                                 harmonics=3, spectral_skip=k)
            torch.testing.assert_close(module(x)["y"], x[:, :, 0].repeat(1, 3))


def test_spectral_skip_equals_its_per_harmonic_reference():
    """The FFT skip equals a plain per-harmonic DFT loop (float64), forward and backward;
    harmonics above K and the mean pass unchanged."""
    torch.manual_seed(2)
    k = 3
    module = OrbitModule(QRNNNet(F, H, num_layers=1), horizon=2, harmonics=3,
                         spectral_skip=k).double()
    with torch.no_grad():
        module.skip_gain.normal_(0.0, 0.5)
    u = torch.randn(B, P, dtype=torch.float64, requires_grad=True)
    got = module.skip(u)                                       # (B, P, 2)
    t = torch.arange(P, dtype=torch.float64)
    ref = torch.zeros(B, P, 2, dtype=torch.float64)
    for out in range(2):
        for n in range(P // 2 + 1):
            c = torch.cos(2 * torch.pi * n * t / P)
            s = torch.sin(2 * torch.pi * n * t / P)
            a, b = u @ c, -(u @ s)                             # rfft bin n = a + i b
            g = (complex(1.0, 0.0) if n == 0 or n > k else
                 complex(1.0 + float(module.skip_gain[out, n - 1, 0].detach()),
                         float(module.skip_gain[out, n - 1, 1].detach())))
            re, im = g.real * a - g.imag * b, g.real * b + g.imag * a
            w = 1.0 if n in (0, P // 2) else 2.0
            ref[:, :, out] += w / P * (re[:, None] * c - im[:, None] * s)
    torch.testing.assert_close(got, ref)
    (gu,) = torch.autograd.grad(got.square().sum(), u)
    (gr,) = torch.autograd.grad(ref.square().sum(), u)
    torch.testing.assert_close(gu, gr)
    # more gains than harmonics (a shorter period): the first P // 2 are used
    wide = OrbitModule(QRNNNet(F, H, num_layers=1), horizon=2, harmonics=3,
                       spectral_skip=P).double()
    with torch.no_grad():
        wide.skip_gain.zero_()
        wide.skip_gain[:, :k] = module.skip_gain
        wide.skip_gain[:, P // 2:] = 5.0                      # beyond P // 2: never used
    torch.testing.assert_close(wide.skip(u), got)
    with pytest.raises(ValueError, match="spectral_skip"):
        OrbitModule(QRNNNet(F, H, num_layers=1), spectral_skip=-1)


def test_period_nrmse_loss_equals_the_metric():
    """The default orbit loss is the mean of evaluate.nrmse_per_period (float64 reference)."""
    g = torch.Generator().manual_seed(1)
    true = torch.randn(5, 4 * P, generator=g, dtype=torch.float64)
    pred = true + 0.1 * torch.randn(5, 4 * P, generator=g, dtype=torch.float64)
    ref = nrmse_per_period(pred.numpy(), true.numpy(), horizon=4).mean()
    loss = PeriodNRMSELoss(eps=1e-30)(pred, true, horizon=4)
    assert abs(float(loss) - ref) < 1e-12
    # every window counts alike: scaling one window's error 10x raises the loss linearly,
    # where the MSE grows with its square
    big = pred.clone()
    big[0] = true[0] + 10 * (pred[0] - true[0])
    e0 = nrmse_per_period(pred.numpy()[:1], true.numpy()[:1], horizon=4).mean()
    assert abs(float(PeriodNRMSELoss(eps=1e-30)(big, true, horizon=4)) - (ref + 9 * e0 / 5)) \
        < 1e-12
    with pytest.raises(ValueError, match="eps"):
        PeriodNRMSELoss(eps=0.0)
    with pytest.raises(ValueError, match="orbit_loss"):
        OrbitModule(QRNNNet(F, H, num_layers=1), orbit_loss="mse")
