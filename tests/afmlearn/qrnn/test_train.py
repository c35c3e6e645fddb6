"""train(cfg) on the tiny data spec: run folder, resume after an interruption, reproducibility,
and the configs (models, experiments, DDP) composing into working objects."""

from __future__ import annotations

import json

import lightning.pytorch as pl
import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf

from afmlearn.qrnn.module import CHECKPOINT_KEY, OrbitModule
from afmlearn.qrnn.train import train


def test_train_writes_checkpoints_logs_metrics_and_export(tiny_run):
    out = tiny_run["objects"]["output_dir"]
    m = tiny_run["metrics"]
    assert m["epochs_completed"] == 2
    assert (out / "checkpoints" / "last.ckpt").is_file()
    assert list((out / "csv").glob("version_*/metrics.csv"))
    assert list((out / "tensorboard").rglob("events.out.tfevents.*"))
    saved = json.loads((out / "metrics.json").read_text())
    for key in ("val/loss", "test/loss", "heldout/nrmse_period_1", "heldout/nrmse_period_2",
                "heldout/vpt_periods", "heldout/coupling_accuracy", "heldout/sweet_iou"):
        assert key in saved and saved[key] == pytest.approx(m[key], nan_ok=True)
    assert 0.0 <= m["heldout/vpt_periods"] <= 2.0
    # the exported checkpoint is slim, loads without pickle and carries the run description
    ckpt = torch.load(tiny_run["checkpoint"], map_location="cpu", weights_only=True)
    run = ckpt[CHECKPOINT_KEY]["run"]
    assert run["input_size"] == 3 and run["horizon"] == 2
    assert run["config"]["model"]["net"]["hidden_size"] == 16
    assert "optimizer_states" not in ckpt
    assert tiny_run["checkpoint"].stat().st_size < 0.5e6


class _CrashAt(pl.Callback):
    """Raise at the start of ``epoch`` (an interruption after ``epoch`` finished epochs)."""

    def __init__(self, epoch: int) -> None:
        self.epoch = epoch

    def on_train_epoch_start(self, trainer, pl_module):
        if trainer.current_epoch == self.epoch:
            raise RuntimeError("simulated interruption")


class _Record(pl.Callback):
    def __init__(self) -> None:
        self.epochs: list[int] = []
        self.start_state: dict[str, torch.Tensor] = {}

    def on_train_start(self, trainer, pl_module):
        self.start_state = {k: v.detach().clone() for k, v in pl_module.state_dict().items()}

    def on_train_epoch_start(self, trainer, pl_module):
        self.epochs.append(trainer.current_epoch)


def test_resume_continues_from_the_last_finished_epoch(compose_train, tmp_path):
    cfg = compose_train(tmp_path, "run_name=resume", "trainer.max_epochs=3", "test=false")
    with pytest.raises(RuntimeError, match="simulated interruption"):
        train(cfg, extra_callbacks=[_CrashAt(2)])
    last = tmp_path / "outputs" / "train_qrnn" / "resume" / "checkpoints" / "last.ckpt"
    saved = torch.load(last, map_location="cpu", weights_only=True)
    assert saved["epoch"] == 1                       # epochs 0 and 1 finished and kept
    steps_per_epoch = saved["global_step"] // 2
    record = _Record()
    metrics, objects = train(cfg, extra_callbacks=[record])
    assert objects["ckpt_path"] == str(last)
    assert record.epochs == [2]                      # only the missing epoch runs
    for k, v in saved["state_dict"].items():         # it starts from the saved weights
        torch.testing.assert_close(record.start_state[k], v)
    assert metrics["epochs_completed"] == 3
    assert metrics["global_step"] == 3 * steps_per_epoch
    # ckpt_path=null starts from scratch
    fresh = _Record()
    train(OmegaConf.merge(cfg, {"ckpt_path": None, "trainer": {"max_epochs": 1}}),
          extra_callbacks=[fresh])
    assert fresh.epochs == [0]


def test_same_seed_same_weights(compose_train, tmp_path):
    states = []
    for name in ("a", "b"):
        cfg = compose_train(tmp_path, f"run_name={name}", "trainer.max_epochs=1", "test=false")
        _, objects = train(cfg)
        states.append(objects["model"].state_dict())
    for k in states[0]:
        torch.testing.assert_close(states[0][k], states[1][k], rtol=0, atol=0)


@pytest.mark.parametrize("overrides", [
    ["model=qrnn", "data.modes=2"], ["model=lstm"], ["model=gru"],
    ["experiment=qrnn_default"], ["experiment=qrnn_autoregressive"], ["experiment=qrnn_smoke"],
])
def test_configs_build_a_module(compose_train, tmp_path, overrides):
    cfg = compose_train(tmp_path, *overrides)
    net = instantiate(cfg.model.net, input_size=3)
    module = instantiate(OmegaConf.create({k: v for k, v in cfg.model.items()
                                           if k not in ("name", "net")}), net=net)
    assert isinstance(module, OrbitModule)
    assert net.hidden_size == cfg.model.net.hidden_size
    opt = module.configure_optimizers()
    assert isinstance(opt["optimizer"], torch.optim.Optimizer)
    y = module(torch.randn(2, 32, 3))["y"]
    assert y.shape == (2, cfg.data.horizon * 32)


def test_ddp_trainer_config_is_constructible(compose_train, tmp_path):
    from lightning.pytorch.strategies import DDPStrategy

    cfg = compose_train(tmp_path, "trainer=ddp", "trainer.accelerator=cpu")
    trainer = instantiate(cfg.trainer, logger=False, enable_checkpointing=False)
    assert isinstance(trainer.strategy, DDPStrategy)
    assert trainer.num_devices == 2 and trainer.num_nodes == 1
