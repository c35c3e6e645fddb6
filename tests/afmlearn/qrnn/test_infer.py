"""Inference on trace files: coupling.json, figures, agreement with the module run by hand,
never reading /labels, the shipped checkpoint, and clear failures on bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from afmlearn.io import Trace, TraceFormatError, read_trace, write_trace
from afmlearn.plots.qrnn import inference_figures
from afmlearn.qrnn.data import windows_from_trace
from afmlearn.qrnn.infer import (
    DEFAULT_CHECKPOINT,
    calibration_of,
    coupling_summary,
    infer,
    load_module,
)

ROOT = Path(__file__).resolve().parents[3]
F0 = 300e3              # Hz
FS = 64 * F0            # 64 samples per period of f0


def _sweep(n_points: int = 6, n: int = 640, *, fs: float = FS) -> Trace:
    """A forward sweep: a sinusoid whose 6th harmonic grows with the drive frequency."""
    f = np.linspace(0.99, 1.02, n_points) * F0
    t = np.arange(n) / fs
    rows = [10e-9 * np.cos(2 * np.pi * fi * t)
            + 1e-9 * k / n_points * np.cos(2 * np.pi * 6 * fi * t + 0.3)
            for k, fi in enumerate(f)]
    return Trace(np.array(rows), sample_rate_hz=fs, spring_constant_n_per_m=40.0,
                 quality_factor=400.0, resonance_frequency_hz=F0, drive_frequency_hz=f,
                 gap_m=12e-9)


def _with_broken_labels(path: Path) -> Path:
    """Add a /labels group that breaks the format: reading it would raise."""
    with h5py.File(path, "a") as fh:
        fh.create_group("labels").create_dataset("force_n", data=np.zeros((2, 3, 4)))
    with pytest.raises(TraceFormatError):
        read_trace(path, labels=True)
    return path


def test_infer_on_a_sweep_file(tiny_run, tmp_path):
    trace = _sweep()
    path = _with_broken_labels(write_trace(trace, tmp_path / "sweep.h5"))
    result = infer(path, tmp_path / "out", checkpoint=tiny_run["checkpoint"], threshold=0.4,
                   figures=inference_figures)
    saved = json.loads((tmp_path / "out" / "coupling.json").read_text())
    assert saved["checkpoint"] == str(Path(tiny_run["checkpoint"]).resolve())
    assert saved["is_sweep"] and saved["n_traces"] == 6 and len(saved["traces"]) == 6
    assert [s["direction"] for s in saved["sweet_spot"]] == ["forward"]
    # reference: the module run by hand on the same windows, mean per row
    module, run, _ = load_module(tiny_run["checkpoint"])
    win = windows_from_trace(trace, samples_per_period=run["samples_per_period"],
                             horizon=run["horizon"])
    scores = module.predict_windows(torch.from_numpy(win["x"]))["coupled"].numpy()
    cal = calibration_of(run)        # train() calibrates on the validation cantilevers
    assert saved["calibrated"] == (cal is not None)
    for row in saved["traces"]:
        ref = scores[win["row"] == row["row"]].mean()
        assert row["raw_score"] == pytest.approx(ref, abs=1e-6)
        prob = ref if cal is None else float(cal.probability([ref])[0])
        assert row["score"] == pytest.approx(prob, abs=1e-6)
        assert row["flag"] == (row["score"] >= 0.4)
        assert row["drive_frequency_hz"] == pytest.approx(trace.drive_frequency_hz[row["row"]])
        assert len(row["forecast_nrmse_per_period"]) == run["horizon"]
    for fig in saved["figures"]:
        assert Path(fig).is_file() and Path(fig).stat().st_size > 1000
    assert {Path(f).name for f in saved["figures"]} == {"prediction.png", "scores.png"}
    assert result["output"] == str(tmp_path / "out" / "coupling.json")


def test_infer_single_trace_and_summary(tiny_run, tmp_path):
    sweep = _sweep(n_points=1)
    single = Trace(sweep.deflection_m[0], **{**sweep.metadata(),
                                             "drive_frequency_hz": sweep.drive_frequency_hz[0]})
    path = tmp_path / "one.h5"
    write_trace(single, path)
    res = infer(path, tmp_path / "o", checkpoint=tiny_run["checkpoint"])
    assert res["figures"] == [] and not list((tmp_path / "o").glob("*.png"))
    assert not res["is_sweep"] and res["sweet_spot"] is None
    assert 0.0 <= res["score"] <= 1.0 and res["flag"] == (res["score"] >= res["threshold"])
    text = coupling_summary(path, checkpoint=tiny_run["checkpoint"])
    assert f"{res['score']:.3f}" in text


@pytest.mark.parametrize("kind, message", [
    ("short", "too short|spans"),
    ("undersampled", "samples per drive period"),
    ("nan", "finite|NaN"),
    ("clipped", "clipped"),
])
def test_bad_inputs_fail_clearly(tiny_run, tmp_path, kind, message):
    path = tmp_path / f"{kind}.h5"
    if kind == "short":
        write_trace(_sweep(n=64 * 2), path)                   # 2 periods < 1 + horizon + 1
    elif kind == "undersampled":
        write_trace(_sweep(fs=12 * F0, n=400), path)          # 12 samples per period
    elif kind == "clipped":                                   # detector saturated at 90 %
        sweep = _sweep()
        top = 0.9 * sweep.deflection_m.max()
        write_trace(Trace(np.minimum(sweep.deflection_m, top), **sweep.metadata()), path)
    else:
        write_trace(_sweep(), path)
        with h5py.File(path, "a") as fh:
            d = fh["deflection_m"][()]
            d[2, 17] = np.nan
            fh["deflection_m"][...] = d
    with pytest.raises(ValueError, match=message):
        infer(path, tmp_path / "out", checkpoint=tiny_run["checkpoint"])
    assert not (tmp_path / "out" / "coupling.json").exists()


def test_missing_checkpoint_and_missing_trace(tmp_path):
    with pytest.raises(ValueError, match="checkpoint"):
        load_module(tmp_path / "nope.ckpt")
    (tmp_path / "junk.ckpt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="checkpoint"):
        load_module(tmp_path / "junk.ckpt")
    with pytest.raises(ValueError, match="no such file"):
        infer(tmp_path / "missing.h5", tmp_path / "out")


@pytest.mark.slow  # a subprocess importing torch, lightning and hydra (~5-20 s)
def test_cli_exits_non_zero_on_bad_input(tiny_run, tmp_path):
    path = tmp_path / "under.h5"
    write_trace(_sweep(fs=12 * F0, n=400), path)
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "infer_qrnn.py"),
                           f"trace={path}", f"out_dir={tmp_path / 'out'}",
                           f"checkpoint={tiny_run['checkpoint']}"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert "error:" in proc.stderr and "samples per drive period" in proc.stderr


def test_shipped_checkpoint_is_small_and_works(tmp_path):
    assert DEFAULT_CHECKPOINT.is_file(), "the package must ship a trained checkpoint"
    assert DEFAULT_CHECKPOINT.stat().st_size < 5e6
    module, run, used = load_module()
    assert used == DEFAULT_CHECKPOINT and run["samples_per_period"] >= 16
    write_trace(_sweep(n=64 * (run["horizon"] + 3)), tmp_path / "s.h5")
    res = infer(tmp_path / "s.h5", tmp_path / "out")
    assert res["checkpoint"] == str(DEFAULT_CHECKPOINT.resolve())
    assert all(0.0 <= t["score"] <= 1.0 for t in res["traces"])


def test_cli_refuses_a_clipped_trace_with_one_line(tiny_run, tmp_path, monkeypatch, capsys):
    """scripts/infer_qrnn.py applies the identify/diagnose input checks: exit 2, one line."""
    import runpy

    sweep = _sweep()
    clipped = Trace(np.clip(sweep.deflection_m, -np.inf, 0.9 * sweep.deflection_m.max()),
                    **sweep.metadata())
    path = write_trace(clipped, tmp_path / "clipped.h5")
    monkeypatch.setattr(sys, "argv", [str(ROOT / "scripts" / "infer_qrnn.py"), f"trace={path}",
                                      f"out_dir={tmp_path / 'out'}",
                                      f"checkpoint={tiny_run['checkpoint']}",
                                      "hydra.output_subdir=null"])
    monkeypatch.syspath_prepend(str(ROOT / "scripts"))  # as `python scripts/x.py` has it
    with pytest.raises(SystemExit) as exc:
        runpy.run_path(str(ROOT / "scripts" / "infer_qrnn.py"), run_name="__main__")
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2
    assert len(err) == 1 and err[0].startswith("error:") and "clipped" in err[0]
    assert not (tmp_path / "out" / "coupling.json").exists()


def test_traces_outside_the_training_band_are_never_flagged(tiny_run, tmp_path):
    """Scored, but not flagged: drive 1.05-1.10 f0 lies outside the trained 0.985-1.03."""
    from afmlearn.qrnn.infer import predict_trace, training_band

    module, run, _ = load_module(tiny_run["checkpoint"])
    lo, hi = training_band(run)
    assert lo <= 0.99 and hi >= 1.02
    inside = predict_trace(_sweep(), module, run, threshold=1e-6)["summary"]
    assert inside["n_out_of_band"] == 0 and all(t["flag"] for t in inside["traces"])
    far = _sweep()
    far = Trace(far.deflection_m, sample_rate_hz=FS, spring_constant_n_per_m=40.0,
                quality_factor=400.0, resonance_frequency_hz=F0,
                drive_frequency_hz=np.linspace(1.05, 1.10, 6) * F0, gap_m=12e-9)
    out = predict_trace(far, module, run, threshold=1e-6)["summary"]
    assert out["n_out_of_band"] == 6 and not any(t["flag"] for t in out["traces"])
    assert all(t["score"] > 1e-6 for t in out["traces"])          # still scored
    assert "never flagged" in coupling_summary(far, checkpoint=tiny_run["checkpoint"])


def test_inference_never_imports_the_plots_layer():
    """Layering: analyses never import afmlearn.plots (the figures are the caller's)."""
    code = ("import sys, afmlearn.qrnn.infer, afmlearn.qrnn.evidence; "
            "print(sorted(m for m in sys.modules if m.startswith('afmlearn.plots')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, check=True).stdout.strip()
    assert out == "[]"
