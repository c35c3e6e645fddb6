"""`write_trace` / `read_trace`: round trips, atomicity, labels only on request."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from afmlearn.io import Trace, TraceFormatError, read_trace, write_trace


def test_single_round_trip(tmp_path: Path, single: Trace, assert_same: Any) -> None:
    path = write_trace(single, tmp_path / "single.h5")
    assert_same(single, read_trace(path, labels=True), labels=True)
    assert read_trace(path).labels is None


def test_sweep_round_trip(tmp_path: Path, sweep: Trace, assert_same: Any) -> None:
    path = write_trace(sweep, tmp_path / "sweep.h5")
    back = read_trace(path, labels=True)
    assert back.is_sweep
    assert_same(sweep, back, labels=True)
    assert back.free_amplitude_m is None and back.excitation is None
    assert read_trace(path).labels is None


def test_layout_follows_design(tmp_path: Path, single: Trace, sweep: Trace) -> None:
    write_trace(single, tmp_path / "single.h5")
    write_trace(sweep, tmp_path / "sweep.h5")
    with h5py.File(tmp_path / "single.h5") as f:
        assert f.attrs["format"] == "afmlearn-trace"
        assert f.attrs["format_version"] == 1
        assert f.attrs["drive_frequency_hz"] == pytest.approx(2.99e5)
        assert f.attrs["excitation"] == "base"
        assert {"deflection_m", "gap_m", "free_deflection_m", "labels"} <= set(f)
        assert "gap_m" not in f.attrs
        assert f["labels"].attrs["effect"] == "higher_mode"
        assert f["labels/dissipated_energy_j"][()] == pytest.approx(1.5e-19)
    with h5py.File(tmp_path / "sweep.h5") as f:
        assert f["deflection_m"].chunks == (1, sweep.n_samples)
        assert f["drive_frequency_hz"].shape == (sweep.n_points,)
        assert f.attrs["gap_m"] == pytest.approx(15e-9)


def test_measured_file_has_no_labels(tmp_path: Path, calibration: dict[str, Any]) -> None:
    trace = Trace(np.ones(10), **calibration, drive_frequency_hz=3e5, gap_m=1e-8)
    path = write_trace(trace, tmp_path / "measured.h5")
    with h5py.File(path) as f:
        assert "labels" not in f
    assert read_trace(path, labels=True).labels is None


def test_labels_false_never_opens_the_group(tmp_path: Path, single: Trace) -> None:
    path = write_trace(single, tmp_path / "t.h5")
    with h5py.File(path, "r+") as f:  # make /labels unopenable: a link to a missing file
        del f["labels"]
        f["labels"] = h5py.ExternalLink("missing.h5", "/labels")
    trace = read_trace(path)
    assert trace.labels is None
    with pytest.raises(TraceFormatError, match="labels"):
        read_trace(path, labels=True)


def test_labels_false_never_touches_labels_names(
    tmp_path: Path, single: Trace, h5_names_seen: list[str]
) -> None:
    path = write_trace(single, tmp_path / "t.h5")
    seen = h5_names_seen  # the spy is installed before writing; start from a clean list
    seen.clear()
    read_trace(path)
    assert seen and not any("labels" in name for name in seen)


def test_overwrite_is_atomic(tmp_path: Path, single: Trace, sweep: Trace) -> None:
    path = tmp_path / "t.h5"
    write_trace(single, path)
    write_trace(sweep, path)
    assert read_trace(path).is_sweep
    assert [p.name for p in tmp_path.iterdir()] == ["t.h5"]


def test_failed_write_leaves_nothing(
    tmp_path: Path, single: Trace, monkeypatch: pytest.MonkeyPatch
) -> None:
    def boom(*args: Any, **kwargs: Any) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(h5py.Group, "create_dataset", boom)
    with pytest.raises(OSError, match="disk full"):
        write_trace(single, tmp_path / "t.h5")
    assert list(tmp_path.iterdir()) == []
