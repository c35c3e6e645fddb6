"""`convert_recording`: an instrument file -> trace format v1 (or a force-curve file)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from afmlearn.io.instruments.force_curve import ForceCurve, write_force_curve
from afmlearn.io.instruments.registry import open_recording
from afmlearn.io.trace import Trace
from afmlearn.io.writer import write_trace

__all__ = ["convert_recording"]


def convert_recording(input_path: str | os.PathLike[str], output: str | os.PathLike[str], *,
                      calibration: Any = None, **overrides: Any) -> list[dict[str, Any]]:
    """Read ``input_path`` with `open_recording` and write it atomically.

    A `Trace` becomes a trace-format-v1 file (design.md section 2, lock-in fields included);
    a static `ForceCurve` an ``afmlearn-forcecurve`` file (docs/recordings.md). A file with
    several curves writes ``<stem>-000<suffix>``, ``<stem>-001<suffix>`` ...

    Returns
    -------
    list of dict
        Per file written: ``path``, ``kind`` ("trace" or "force_curve"), ``n_samples``.
    """
    opened = open_recording(input_path, calibration=calibration, **overrides)
    records = opened if isinstance(opened, list) else [opened]
    output = Path(output)
    output.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for i, record in enumerate(records):
        path = output if len(records) == 1 else output.with_name(
            f"{output.stem}-{i:03d}{output.suffix}")
        if isinstance(record, Trace):
            write_trace(record, path)
            n = record.n_samples
            kind = "trace"
        else:
            assert isinstance(record, ForceCurve)
            write_force_curve(record, path)
            n = record.n_points
            kind = "force_curve"
        written.append({"path": str(path), "kind": kind, "n_samples": int(n)})
    return written
