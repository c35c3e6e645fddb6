"""Datasets of many traces: a folder of shard files ``shard-00000.h5`` ... and a manifest.

Each shard is an ordinary trace file. ``manifest.json`` is rebuilt from the shards present
(`write_manifest`), so processes writing shards independently never race on it::

    {"format": "afmlearn-dataset", "format_version": 1, "n_files": 2,
     "files": [{"file": "shard-00000.h5", "shard": 0, "n_points": 1, "n_samples": 4096,
                "sample_rate_hz": 5e6, "drive_frequency_hz": [3e5, 3e5]}, ...]}

``shard`` is the position of the file in the name-sorted listing (equal to the number in its
name when shards are written by `shard_path` without gaps); ``drive_frequency_hz`` is the
[min, max] range of the file's drive frequencies [Hz].
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from afmlearn.io._atomic import atomic_path
from afmlearn.io._checks import count
from afmlearn.io.errors import TraceFormatError
from afmlearn.io.reader import TraceReader, read_trace
from afmlearn.io.trace import Trace

__all__ = ["MANIFEST", "iter_traces", "shard_path", "write_manifest"]

MANIFEST = "manifest.json"
DATASET_FORMAT = "afmlearn-dataset"


def shard_path(folder: str | os.PathLike[str], index: int) -> Path:
    """Path of shard ``index`` (>= 0) in ``folder``: ``folder/shard-00042.h5``."""
    return Path(folder) / f"shard-{count('index', index, minimum=0):05d}.h5"


def write_manifest(folder: str | os.PathLike[str]) -> Path:
    """Rebuild ``folder/manifest.json`` from the ``*.h5`` files present, atomically.

    Every file is opened and its metadata validated (the arrays are not loaded).

    Parameters
    ----------
    folder : str or os.PathLike
        The dataset folder.

    Returns
    -------
    pathlib.Path
        Path of the manifest.

    Raises
    ------
    TraceFormatError
        If a file in the folder is not a valid trace file.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"folder must be an existing directory, got {folder}")
    entries = []
    for shard, path in enumerate(sorted(folder.glob("*.h5"))):
        with TraceReader(path) as reader:
            drive = np.atleast_1d(reader.metadata["drive_frequency_hz"])
            entries.append(
                {
                    "file": path.name,
                    "shard": shard,
                    "n_points": reader.n_points,
                    "n_samples": reader.n_samples,
                    "sweep": reader.is_sweep,
                    "sample_rate_hz": reader.metadata["sample_rate_hz"],
                    "drive_frequency_hz": [float(drive.min()), float(drive.max())],
                }
            )
    manifest = {
        "format": DATASET_FORMAT,
        "format_version": 1,
        "n_files": len(entries),
        "files": entries,
    }
    target = folder / MANIFEST
    with atomic_path(target) as tmp:
        tmp.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    return target


def iter_traces(path: str | os.PathLike[str], *, labels: bool = False) -> Iterator[Trace]:
    """Yield the traces of a trace file or dataset folder one at a time.

    Parameters
    ----------
    path : str or os.PathLike
        A trace file, or a folder: its files are taken from ``manifest.json`` if present,
        else all ``*.h5`` files sorted by name.
    labels : bool, default False
        Attach the labels (see `read_trace`).

    Yields
    ------
    Trace
        One per file; ``deflection_m`` of shape (n,) or (n_points, n).
    """
    path = Path(path)
    if path.is_dir():
        files = _manifest_files(path) if (path / MANIFEST).exists() else sorted(path.glob("*.h5"))
    else:
        files = [path]
    for file in files:
        yield read_trace(file, labels=labels)


def _manifest_files(folder: Path) -> list[Path]:
    manifest = folder / MANIFEST
    try:
        data: Any = json.loads(manifest.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise TraceFormatError(f"{manifest}: not a readable JSON file ({err})") from err
    if not isinstance(data, dict) or data.get("format") != DATASET_FORMAT:
        raise TraceFormatError(f"{manifest}: key 'format' must be {DATASET_FORMAT!r}")
    files = data.get("files")
    if not isinstance(files, list) or not all(
        isinstance(entry, dict) and isinstance(entry.get("file"), str) for entry in files
    ):
        raise TraceFormatError(f"{manifest}: key 'files' must be a list of {{'file': name, ...}}")
    return [folder / entry["file"] for entry in files]
