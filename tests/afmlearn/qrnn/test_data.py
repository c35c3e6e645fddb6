"""QRNN data: labels, window representation, cache, split by cantilever, recorded traces."""

from __future__ import annotations

import math
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate

from afmlearn.io import Trace, write_trace
from afmlearn.qrnn import datagen
from afmlearn.qrnn.data import SweepDataModule, windows_from_trace
from afmlearn.qrnn.datagen import (
    DatasetSpec,
    generate_dataset,
    normalise_windows,
    resample_windows,
    sweet_interval,
)
from simulator.labels import coupling_strength

ROOT = Path(__file__).resolve().parents[3]

TINY = dict(n_cantilevers=4, sweeps_per_cantilever=1, sweet_spot_fraction=0.25, modes=(2, 3, 1),
            n_points=8, settle_periods=5.0, record_periods=6, initial_settle_periods=30.0,
            sim_samples_per_period=64, samples_per_period=32, target_periods=4,
            windows_per_point=1)


@pytest.fixture(scope="module")
def tiny_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("qrnn") / "tiny.h5"
    return generate_dataset(path, spec=DatasetSpec(**TINY), progress=False)


# ---------------------------------------------------------------- labels
def test_sweet_interval_bridges_gaps_and_picks_longest_run():
    om = np.linspace(1.0, 1.011, 12)
    cand = np.array([1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 1, 0], dtype=bool)
    interval, mask = sweet_interval(om, cand, max_gap=2, min_points=2)
    # runs with gaps <= 2 bridged: {0}, {4, 6, 7, 10}; the second has 4 candidates
    assert interval == pytest.approx((om[4], om[10]))
    assert np.array_equal(np.flatnonzero(mask), np.arange(4, 11))
    interval, mask = sweet_interval(om, cand, max_gap=0, min_points=2)
    assert interval == pytest.approx((om[6], om[7]))
    assert sweet_interval(om, cand, max_gap=0, min_points=3)[0] is None
    assert sweet_interval(om, np.zeros(12, bool))[0] is None
    # reverse sweep order: the interval is still (min, max) of the run
    interval, _ = sweet_interval(om[::-1], cand[::-1], max_gap=2)
    assert interval == pytest.approx((om[4], om[10]))


def test_spec_validation_and_hash():
    with pytest.raises(ValueError, match="record_periods"):
        DatasetSpec(record_periods=3, target_periods=4)
    with pytest.raises(ValueError, match="modes"):
        DatasetSpec(modes=(4,))
    with pytest.raises(ValueError, match="coupling_threshold"):
        DatasetSpec(coupling_threshold=0.0)
    with pytest.raises(ValueError, match="unknown"):
        DatasetSpec.from_dict({"n_cantilever": 3})
    a = DatasetSpec.from_dict({"modes": [1, 2], "noise_levels": [0.0]})
    assert a == DatasetSpec(modes=(1, 2), noise_levels=(0.0,))
    assert a.hash == DatasetSpec(modes=(1, 2), noise_levels=(0.0,)).hash != DatasetSpec().hash


# ---------------------------------------------------------------- representation
def test_resample_and_normalise_recover_a_sinusoid():
    period = 37.3  # raw samples per drive period (non-integer)
    n = 400
    t = np.arange(n)
    x = 0.3 + 2.0 * np.sin(2 * np.pi * t / period + 0.4)
    starts = np.array([0.0, 11.7, 150.2])
    p = 64
    w = resample_windows(x, period=period, starts=starts, n_periods=3, samples_per_period=p)
    tk = starts[:, None] + np.arange(3 * p)[None, :] * period / p
    assert np.max(np.abs(w - (0.3 + 2.0 * np.sin(2 * np.pi * tk / period + 0.4)))) < 2e-3
    u, offset, scale = normalise_windows(w, p)
    np.testing.assert_allclose(offset, 0.3, atol=2e-3)
    np.testing.assert_allclose(scale, 2.0, rtol=2e-3)  # sqrt(2) std of a sine = its amplitude
    np.testing.assert_allclose(u, np.sin(2 * np.pi * tk / period + 0.4), atol=3e-3)
    with pytest.raises(ValueError, match="inside"):
        resample_windows(x, period=period, starts=np.array([300.0]), n_periods=3,
                         samples_per_period=p)


def _sine_trace(*, n=2000, fs=1e6, f0=2e4, f_drive=(2.02e4,), amp=30e-9, gap=100e-9):
    t = np.arange(n) / fs
    rows = np.stack([5e-9 + amp * np.cos(2 * np.pi * f * t) for f in f_drive])
    sweep = len(f_drive) > 1
    return Trace(rows if sweep else rows[0], sample_rate_hz=fs, spring_constant_n_per_m=2.0,
                 quality_factor=300.0, resonance_frequency_hz=f0,
                 drive_frequency_hz=np.array(f_drive) if sweep else f_drive[0], gap_m=gap)


def test_windows_from_trace_matches_the_analytic_signal():
    fs, f0, fd, amp, gap = 1e6, 2e4, 2.02e4, 30e-9, 100e-9
    tr = _sine_trace(fs=fs, f0=f0, f_drive=(fd,), amp=amp, gap=gap)
    out = windows_from_trace(tr, samples_per_period=32, horizon=3)
    period = fs / fd
    n_expected = len(np.arange(0.0, 2000 - 1 - 4 * period + 1e-9, period))
    assert out["x"].shape == (n_expected, 32, 3) and out["x"].dtype == np.float32
    assert out["y"].shape == (n_expected, 3 * 32)
    phase = 2 * np.pi * (out["start_s"][:, None] * fd + np.arange(4 * 32)[None, :] / 32)
    full = np.concatenate([out["x"][:, :, 0], out["y"]], axis=1)
    np.testing.assert_allclose(full, np.cos(phase), atol=2e-3)  # continues the input period
    np.testing.assert_allclose(out["x"][:, :, 1], 10 * (fd / f0 - 1), rtol=1e-6)
    np.testing.assert_allclose(out["x"][:, :, 2], amp / gap, rtol=2e-3)
    np.testing.assert_allclose(out["offset_m"], 5e-9, atol=1e-11)
    assert not out["is_sweep"] and np.all(out["row"] == 0)


def test_windows_from_trace_sweep_file(tmp_path):
    tr = _sine_trace(f_drive=(1.9e4, 2.0e4, 2.1e4))
    path = tmp_path / "sweep.h5"
    write_trace(tr, path)
    out = windows_from_trace(path, samples_per_period=32, horizon=2, stride=2.0)
    assert out["is_sweep"] and set(out["row"].tolist()) == {0, 1, 2}
    np.testing.assert_allclose(out["omega_rows"], [0.95, 1.0, 1.05])
    np.testing.assert_allclose(out["omega"], out["omega_rows"][out["row"]])


def test_windows_from_trace_rejects_bad_input():
    with pytest.raises(ValueError, match="too short"):
        windows_from_trace(_sine_trace(n=200), samples_per_period=32, horizon=4)
    with pytest.raises(ValueError, match="samples per drive period"):
        windows_from_trace(_sine_trace(fs=3e5), samples_per_period=32, horizon=1)
    with pytest.raises(ValueError, match="finite"):
        _sine_trace(n=2000).__class__(np.full(100, np.nan), **_sine_trace().metadata())
    with pytest.raises(ValueError, match="horizon"):
        windows_from_trace(_sine_trace(), samples_per_period=32, horizon=0)
    with pytest.raises(ValueError, match="gap_m"):
        windows_from_trace(_sine_trace(gap=-1e-9), samples_per_period=32, horizon=1)


# ---------------------------------------------------------------- generated dataset
def test_dataset_labels_follow_their_definitions(tiny_file):
    spec = DatasetSpec(**TINY)
    with h5py.File(tiny_file, "r") as fh:
        assert fh.attrs["spec_hash"] == spec.hash
        pts = {k: fh["points"][k][()] for k in fh["points"]}
        win = {k: fh["windows"][k][()] for k in fh["windows"]}
        swp = {k: fh["sweeps"][k][()] for k in fh["sweeps"]}
    assert win["u"].shape == (spec.n_windows, (1 + spec.target_periods) * 32)
    np.testing.assert_array_equal(pts["coupled"], pts["coupling"] > spec.coupling_threshold)
    one_mode = swp["n_modes"][pts["sweep_id"]] == 1
    assert one_mode.any() and np.all(pts["coupling"][one_mode] == 0.0)
    np.testing.assert_allclose(pts["shares"].sum(axis=1), 1.0, rtol=1e-5)
    assert np.all(pts["shares"][one_mode][:, 1:] == 0.0)
    # sweet points are exactly the run of coupled, tapping points of their sweep
    for s in range(swp["direction"].size):
        rows = np.flatnonzero(pts["sweep_id"] == s)
        rows = rows[np.argsort(pts["point_index"][rows])]
        cand = pts["coupled"][rows] & (pts["contact_fraction"][rows] > 0)
        interval, mask = sweet_interval(pts["omega"][rows], cand, max_gap=spec.sweet_max_gap,
                                        min_points=spec.sweet_min_points)
        np.testing.assert_array_equal(pts["sweet"][rows], mask)
        assert (interval is None) == np.isnan(swp["sweet_lo"][s])
        om = pts["omega"][rows]
        step = np.diff(om)
        assert np.all(step > 0) if swp["direction"][s] == 0 else np.all(step < 0)
    # every window is normalised by its input period and carries its point's labels
    first = win["u"][:, :32].astype(float)
    np.testing.assert_allclose(first.mean(axis=1), 0.0, atol=1e-5)
    np.testing.assert_allclose(np.sqrt(2) * first.std(axis=1), 1.0, rtol=1e-4)
    np.testing.assert_array_equal(win["coupled"], pts["coupled"][win["point"]])
    np.testing.assert_allclose(win["omega"], pts["omega"][win["point"]])


def test_coupling_label_is_the_simulator_definition():
    q = np.stack([np.sin(np.linspace(0, 20, 500)), 0.1 * np.sin(np.linspace(0, 120, 500))])
    share = np.var(q[1]) / (np.var(q[0]) + np.var(q[1]))
    assert coupling_strength(q) == pytest.approx(share)
    assert share == pytest.approx(0.01 / 1.01, rel=0.05)  # amplitude ratio 0.1


def test_cache_is_reused_and_generation_resumes(tmp_path, monkeypatch):
    spec = DatasetSpec(**{**TINY, "n_cantilevers": 3, "modes": (1,), "n_points": 4})
    path = tmp_path / "d.h5"
    calls: list[int] = []
    real = datagen._simulate_cantilever

    def flaky(spec_, index):
        calls.append(index)
        if index == 2 and calls.count(2) == 1:
            raise KeyboardInterrupt
        return real(spec_, index)

    monkeypatch.setattr(datagen, "_simulate_cantilever", flaky)
    with pytest.raises(KeyboardInterrupt):
        generate_dataset(path, spec=spec, progress=False)
    assert not path.exists() and calls == [0, 1, 2]
    generate_dataset(path, spec=spec, progress=False)
    assert calls == [0, 1, 2, 2]  # resumed: only the unfinished cantilever ran again
    assert not path.with_name(path.name + ".parts").exists()
    mtime = os.path.getmtime(path)
    generate_dataset(path, spec=spec, progress=False)
    assert calls == [0, 1, 2, 2] and os.path.getmtime(path) == mtime
    with h5py.File(path, "r") as fh:
        assert fh.attrs["n_cantilevers"] == 3 and fh.attrs["spec_hash"] == spec.hash


# ---------------------------------------------------------------- data module
def _tiny_module(tmp_path, **overrides) -> SweepDataModule:
    with initialize_config_dir(str(ROOT / "conf" / "data"), version_base="1.3"):
        cfg = compose("qrnn_tiny", overrides=[f"cache_dir={tmp_path}",
                                              *[f"{k}={v}" for k, v in overrides.items()]])
    return instantiate(cfg)


def test_datamodule_batches_and_split_by_cantilever(tmp_path):
    dm = _tiny_module(tmp_path)
    dm.prepare_data()
    dm.setup()
    ids = dm.cantilevers_
    assert all(ids[k].size >= 1 for k in ids)
    assert not (set(ids["train"]) & set(ids["test"]) or set(ids["train"]) & set(ids["val"])
                or set(ids["val"]) & set(ids["test"]))
    batch = next(iter(dm.train_dataloader()))
    p = dm.samples_per_period
    b = batch["x"].shape[0]
    assert batch["x"].shape == (b, p, dm.n_features) and batch["x"].dtype == torch.float32
    assert batch["y"].shape == (b, dm.horizon * p)
    for key in ("coupling", "coupled", "sweet", "omega", "sweep_id", "point"):
        assert batch[key].shape == (b,)
    detuning = (10 * (batch["omega"][:, None] - 1)).expand(-1, p)
    np.testing.assert_allclose(batch["x"][:, :, 1].numpy(), detuning.numpy(), atol=1e-5)
    n_total = sum(len(dm.dataset(s)) for s in ("train", "val", "test"))
    assert n_total == dm.spec.n_windows
    test_sweeps = dm.sweeps("test")
    assert {s["cantilever_id"] for s in test_sweeps} == set(ids["test"].tolist())
    assert all(s["omega"].size == dm.spec.n_points for s in test_sweeps)


def test_datamodule_modes_filter_and_bad_settings(tmp_path):
    dm = _tiny_module(tmp_path, modes=1)
    with pytest.raises(ValueError, match="modes=\\(1,\\)"):
        dm.setup()  # only one 1-mode cantilever in the tiny set
    spec = dm.spec
    with pytest.raises(ValueError, match="horizon"):
        SweepDataModule(cache_dir=tmp_path, spec=spec, horizon=spec.target_periods + 1)
    with pytest.raises(ValueError, match="split"):
        SweepDataModule(cache_dir=tmp_path, spec=spec, split=(0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="modes"):
        SweepDataModule(cache_dir=tmp_path, modes=4)


def test_simulated_sweep_gives_the_same_windows_through_a_trace(tmp_path):
    """A simulated point written as a recording yields the training representation."""
    from simulator import Cantilever, Sweep, System, TipExcitation
    from simulator.forces import DMT

    cl = Cantilever.rectangular(n_modes=2, quality_factor=100.0)
    sysm = System(cl, DMT(a0=0.2, vdw=3e-4, stiffness=10.0),
                  TipExcitation.for_free_amplitude(cl, 1.0, 1.1))
    sw = Sweep(omega_start=0.99, omega_stop=1.01, n_points=2, samples_per_point=640,
               samples_per_period=64, settle_periods=50, direction="forward")
    res = sw.run(sysm)
    ell, f0 = 50e-9, 3e5
    tr = Trace(res.deflection * ell, sample_rate_hz=f0 * 64, spring_constant_n_per_m=1.0,
               quality_factor=100.0, resonance_frequency_hz=f0,
               drive_frequency_hz=res.omega * f0, gap_m=ell)
    out = windows_from_trace(tr, samples_per_period=32, horizon=2)
    row = 1
    sel = out["row"] == row
    period = 2 * math.pi / (res.omega[row] * res.dt)
    starts = out["start_s"][sel] * tr.sample_rate_hz
    w = resample_windows(res.deflection[row], period=period, starts=starts, n_periods=3,
                         samples_per_period=32)
    u, _, scale = normalise_windows(w, 32)
    x = datagen.input_features(u[:, :32], np.full(starts.size, res.omega[row]), scale)
    np.testing.assert_allclose(out["x"][sel], x, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(out["y"][sel], u[:, 32:], atol=1e-5)
