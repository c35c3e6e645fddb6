"""`analyse_file`: a static force-curve file in, ``report.json`` out (what
scripts/analyze_force_curve.py does).

The file is an instrument file (``.ibw`` contact curve, ``.jpk-force`` and the other
afmformats formats, a CSV / NPZ with ``force_*`` and ``z_piezo_*`` columns) or an
``afmlearn-forcecurve`` ``.h5`` written by scripts/convert.py.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from afmlearn.forcecurve.analysis import analyse_curve
from afmlearn.io import write_json
from afmlearn.io.instruments import ForceCurve, RecordingError, open_recording, read_force_curve

__all__ = ["open_force_curve", "analyse_file"]


def open_force_curve(path: str | os.PathLike[str], *, index: int = 0,
                     **calibration: Any) -> ForceCurve:
    """The ``index``-th static force curve of ``path``.

    Raises
    ------
    RecordingError
        One line: unreadable file, or a file that holds no static force curve (a trace).
    ValueError
        ``index`` out of range.
    """
    path = Path(path)
    if path.suffix.lower() in (".h5", ".hdf5"):
        if calibration:
            raise ValueError("calibration overrides apply to instrument files, not to a "
                             "converted .h5 force curve")
        curves = [read_force_curve(path)]
    else:
        opened = open_recording(path, **calibration)
        curves = [c for c in (opened if isinstance(opened, list) else [opened])
                  if isinstance(c, ForceCurve)]
    if not curves:
        raise RecordingError(f"{path}: holds no static force curve (a dynamic record or a "
                             "lock-in curve: use scripts/identify.py or scripts/diagnose.py)")
    if not 0 <= index < len(curves):
        raise ValueError(f"index must be in [0, {len(curves) - 1}] for {path}, got {index}")
    return curves[index]


def analyse_file(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                 index: int = 0, baseline_fraction: float = 0.3,
                 **calibration: Any) -> dict[str, Any]:
    """Open a static force curve, run `analyse_curve` and write ``<out_dir>/report.json``.

    Returns
    -------
    dict
        `analyse_curve`'s result (SI units) plus ``input``, ``index`` and the curve's
        ``spring_constant_n_per_m`` (None when the file states none).
    """
    if not 0.0 < baseline_fraction < 1.0:
        raise ValueError(f"baseline_fraction must be in (0, 1), got {baseline_fraction}")
    curve = open_force_curve(path, index=index, **calibration)
    report = {"input": str(path), "index": int(index),
              "spring_constant_n_per_m": curve.spring_constant_n_per_m,
              **analyse_curve(curve, baseline_fraction=baseline_fraction)}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "report.json", report)
    return report
