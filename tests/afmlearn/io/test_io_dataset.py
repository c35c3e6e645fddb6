"""Dataset folders: shard files plus ``manifest.json``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from afmlearn.io import (
    MANIFEST,
    Trace,
    TraceFormatError,
    iter_traces,
    shard_path,
    write_manifest,
    write_trace,
)


@pytest.fixture
def folder(tmp_path: Path, single: Trace, sweep: Trace) -> Path:
    """Three shards written independently (as separate processes would), no manifest."""
    for index, trace in enumerate([sweep, single, sweep]):
        write_trace(trace, shard_path(tmp_path, index))
    return tmp_path


def test_shard_names(tmp_path: Path) -> None:
    assert shard_path(tmp_path, 42) == tmp_path / "shard-00042.h5"
    with pytest.raises(ValueError, match="index"):
        shard_path(tmp_path, -1)


def test_manifest_round_trip(folder: Path, single: Trace, sweep: Trace, assert_same: Any) -> None:
    path = write_manifest(folder)
    assert path == folder / MANIFEST
    manifest = json.loads(path.read_text())
    assert manifest["format"] == "afmlearn-dataset" and manifest["n_files"] == 3
    first, second = manifest["files"][:2]
    assert first == {
        "file": "shard-00000.h5",
        "shard": 0,
        "n_points": sweep.n_points,
        "n_samples": sweep.n_samples,
        "sweep": True,
        "sample_rate_hz": sweep.sample_rate_hz,
        "drive_frequency_hz": [2.9e5, 3.1e5],
    }
    assert (second["shard"], second["n_points"], second["sweep"]) == (1, 1, False)
    assert second["drive_frequency_hz"] == [2.99e5, 2.99e5]
    traces = list(iter_traces(folder, labels=True))
    for expected, trace in zip([sweep, single, sweep], traces, strict=True):
        assert_same(expected, trace, labels=True)
    assert all(trace.labels is None for trace in iter_traces(folder))
    assert sorted(p.name for p in folder.iterdir()) == [
        MANIFEST,
        "shard-00000.h5",
        "shard-00001.h5",
        "shard-00002.h5",
    ]


def test_manifest_decides_the_files(folder: Path) -> None:
    write_manifest(folder)
    shard_path(folder, 1).rename(folder / "unlisted.h5.bak")
    with pytest.raises(TraceFormatError, match="shard-00001.h5: no such file"):
        list(iter_traces(folder))
    write_manifest(folder)  # rebuilt from the files present
    assert len(list(iter_traces(folder))) == 2


def test_folder_without_manifest_is_scanned(folder: Path) -> None:
    (folder / "notes.txt").write_text("ignored")
    assert [trace.is_sweep for trace in iter_traces(folder)] == [True, False, True]


def test_missing_path(tmp_path: Path) -> None:
    with pytest.raises(TraceFormatError, match="nothing.h5: no such file"):
        list(iter_traces(tmp_path / "nothing.h5"))


def test_single_file(folder: Path, single: Trace, assert_same: Any) -> None:
    (trace,) = iter_traces(shard_path(folder, 1))
    assert_same(single, trace, labels=False)


def test_bad_manifest(folder: Path) -> None:
    (folder / MANIFEST).write_text("{not json")
    with pytest.raises(TraceFormatError, match="manifest.json: not a readable JSON"):
        list(iter_traces(folder))
    (folder / MANIFEST).write_text(json.dumps({"format": "other"}))
    with pytest.raises(TraceFormatError, match="'format'"):
        list(iter_traces(folder))


def test_manifest_rejects_bad_shards(folder: Path) -> None:
    shard_path(folder, 3).write_text("not hdf5")
    with pytest.raises(TraceFormatError, match="shard-00003.h5"):
        write_manifest(folder)
    assert not (folder / MANIFEST).exists()
