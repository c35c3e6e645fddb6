"""afmlearn.plots: every figure is written, non-empty, from files, Traces and results."""

from __future__ import annotations

from pathlib import Path

import pytest

from afmlearn.io import read_trace
from afmlearn.plots import harmonic_amplitude, plot_sweep, plot_trace
from simulator import Sweep

PNG = b"\x89PNG\r\n\x1a\n"


def assert_pngs(paths: list[Path], names: list[str]) -> None:
    assert [p.name for p in paths] == names
    for p in paths:
        data = p.read_bytes()
        assert data.startswith(PNG) and len(data) > 10_000
    assert not list(paths[0].parent.glob(".*.tmp"))  # atomic: no leftovers


@pytest.fixture
def steady(run_sim, tiny):
    return run_sim("force=dmt_visco", "cantilever=nclr", *tiny["steady"], name="steady.h5")


@pytest.fixture
def sweep(run_sim, tiny):
    return run_sim("scenario=sweep", "cantilever=nclr", *tiny["sweep"], name="sweep.h5")


def test_plot_trace_from_file(tmp_path, steady):
    metrics, _ = steady
    paths = plot_trace(metrics["output"], tmp_path / "fig")
    assert_pngs(paths, ["trace_deflection.png", "trace_phase_portrait.png",
                        "trace_spectrum.png", "trace_force.png"])


def test_plot_trace_without_labels_has_no_force_figure(tmp_path, steady):
    metrics, _ = steady
    paths = plot_trace(read_trace(metrics["output"]), tmp_path, prefix="nolab")
    assert_pngs(paths, ["nolab_deflection.png", "nolab_phase_portrait.png",
                        "nolab_spectrum.png"])


def test_plot_trace_from_result_needs_scales(tmp_path, steady):
    _, obj = steady
    with pytest.raises(ValueError, match="scales"):
        plot_trace(obj["result"], tmp_path)
    paths = plot_trace(obj["result"], tmp_path, scales=obj["scales"], prefix="res")
    assert len(paths) == 4
    assert_pngs(paths, [p.name for p in paths])


def test_plot_trace_of_a_sweep_row(tmp_path, sweep):
    metrics, _ = sweep
    paths = plot_trace(metrics["output"], tmp_path, row=0, prefix="row")
    assert len(paths) == 4
    with pytest.raises(ValueError, match="row"):
        plot_trace(metrics["output"], tmp_path, row=99)


def test_plot_sweep_from_file_trace_and_result(tmp_path, sweep):
    metrics, obj = sweep
    assert_pngs(plot_sweep(metrics["output"], tmp_path, prefix="a"), ["a.png"])
    assert_pngs(plot_sweep(read_trace(metrics["output"]), tmp_path, prefix="b"), ["b.png"])
    sc: Sweep = obj["scenario"]
    result = Sweep(omega_start=sc.omega_start, omega_stop=sc.omega_stop, n_points=3,
                   samples_per_point=300, settle_periods=5,
                   samples_per_period=sc.samples_per_period).run(obj["system"])
    assert_pngs(plot_sweep(result, tmp_path, scales=obj["scales"], prefix="c"), ["c.png"])


def test_plot_sweep_rejects_bad_input(tmp_path, steady, sweep):
    with pytest.raises(ValueError, match="not a sweep"):
        plot_sweep(steady[0]["output"], tmp_path)
    with pytest.raises(ValueError, match="harmonic"):
        plot_sweep(sweep[0]["output"], tmp_path, harmonic=1)
    with pytest.raises(ValueError, match="sweep must be"):
        plot_sweep(42, tmp_path)


def test_harmonic_amplitude():
    import numpy as np

    fs, f = 1000.0, 10.0
    t = np.arange(1234) / fs
    x = 2.0 * np.cos(2 * np.pi * f * t) + 0.5 * np.sin(2 * np.pi * 6 * f * t + 0.3)
    assert harmonic_amplitude(x, fs, f, 1) == pytest.approx(2.0, rel=1e-9)
    assert harmonic_amplitude(x, fs, f, 6) == pytest.approx(0.5, rel=1e-9)
    assert harmonic_amplitude(x, fs, f, 3) == pytest.approx(0.0, abs=1e-12)
