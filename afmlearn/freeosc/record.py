"""Diagnose a free-oscillation recording file end to end (the diagnose_free entry point).

Opens the file with `afmlearn.io.instruments.open_recording` (calibration overrides as
keyword arguments; only the deflection and the sampling rate are used), runs `diagnose_free`,
writes ``report.json`` atomically and hands the result to an optional figure callback (the
entry point passes `afmlearn.plots.freeosc`; the analysis never imports plots).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from afmlearn.freeosc.diagnose import FreeOscillationDiagnosis, diagnose_free
from afmlearn.io import Trace, jsonable, write_json
from afmlearn.io.instruments import open_recording

__all__ = ["diagnose_recording"]

FigureCallback = Callable[[FreeOscillationDiagnosis, np.ndarray, np.ndarray, Path, str],
                          list[Path]]


def diagnose_recording(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                       heldout_fraction: float = 0.3, lever_q: float | None = None,
                       block_periods: int = 200, figures: FigureCallback | None = None,
                       **recording: Any) -> dict[str, Any]:
    """Diagnose the free oscillation recorded in ``path``; returns the report (as written).

    Parameters
    ----------
    path : str or os.PathLike
        A recording `open_recording` reads as one deflection `Trace`.
    out_dir : str or os.PathLike
        Receives ``report.json`` (and the figures).
    heldout_fraction, block_periods
        See `diagnose_free`.
    lever_q : float, optional
        The lever's Q for the transfer-function phases (None: the high-Q limit; the file's or
        the override's ``quality_factor`` is *not* used, placeholders being common there).
    figures : callable, optional
        ``figures(diagnosis, y_nm, prediction_nm, out_dir, unit) -> list of paths``.
    **recording
        `open_recording` options and calibration overrides (``column``, ``unit``,
        ``sample_rate_hz`` ...).

    Raises
    ------
    ValueError
        (`RecordingError` included) on an unreadable file, missing calibration, a record that
        is not a single deflection time series, or bad settings.
    """
    opened = open_recording(path, **recording)
    if not isinstance(opened, Trace) or opened.deflection_m is None \
            or np.ndim(opened.deflection_m) != 1:
        raise ValueError(f"{path}: not a single deflection time series")
    y_nm = np.asarray(opened.deflection_m, dtype=float) * 1e9
    q = math.inf if lever_q is None else float(lever_q)
    diagnosis = diagnose_free(y_nm, sample_rate_hz=opened.sample_rate_hz,
                              heldout_fraction=heldout_fraction, quality_factor=q,
                              block_periods=block_periods)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = diagnosis.to_dict()
    report["record"] = {"path": str(path), "units": "nm as read (detector calibration of the "
                        "file, possibly undocumented)", "n_samples": int(y_nm.size),
                        "sample_rate_hz": float(opened.sample_rate_hz)}
    report["figures"] = []
    if figures is not None:
        paths = figures(diagnosis, y_nm, diagnosis.predict(), out, "nm")
        report["figures"] = [str(p.relative_to(out)) for p in paths]
    write_json(out / "report.json", jsonable(report))
    return report
