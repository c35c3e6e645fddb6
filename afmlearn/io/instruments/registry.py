"""Which reader opens a file, and `open_recording`, the one entry point for instrument files."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from afmlearn.io.instruments.afmformats_files import AfmformatsReader
from afmlearn.io.instruments.asylum import AsylumReader
from afmlearn.io.instruments.base import InstrumentReader
from afmlearn.io.instruments.calibration import THERMAL_FIELDS
from afmlearn.io.instruments.errors import MissingCalibration, RecordingError
from afmlearn.io.instruments.fm_table import is_fm_table
from afmlearn.io.instruments.force_curve import ForceCurve
from afmlearn.io.instruments.nanosurf import NanosurfReader
from afmlearn.io.instruments.table import (
    CsvReader,
    Hdf5SeriesReader,
    NpzReader,
    is_convention_csv,
)
from afmlearn.io.trace import Trace

__all__ = ["READERS", "is_instrument_file", "open_recording", "open_trace", "open_traces",
           "reader_for"]

#: one instance per format; the first whose suffixes match wins (CSV: see `reader_for`)
READERS: tuple[InstrumentReader, ...] = (AsylumReader(), NanosurfReader(), NpzReader(),
                                         CsvReader(), AfmformatsReader(), Hdf5SeriesReader())


def _suffix(path: Path) -> str:
    name = path.name.lower()
    for reader in READERS:
        for suffix in reader.suffixes:
            if name.endswith(suffix):
                return suffix
    return path.suffix.lower()


def _is_binary(path: Path) -> bool:
    """NUL or other control bytes (not tab/CR/LF/FF) in the first 4 kB; any 8-bit text
    encoding (UTF-8, Latin-1 "µm") is text. A missing file is left to the reader."""
    try:
        with path.open("rb") as f:
            head = f.read(4096)
    except OSError:
        return False
    return any(b < 32 and b not in (9, 10, 12, 13) for b in head)


def reader_for(path: str | os.PathLike[str]) -> InstrumentReader:
    """The reader of ``path`` by its suffix (a ``.csv`` goes to `CsvReader` when its header
    follows the column convention, else to afmformats); `RecordingError` if none fits."""
    path = Path(path)
    suffix = _suffix(path)
    if suffix == ".csv":
        if _is_binary(path):
            raise RecordingError(f"{path}: binary content, not a text CSV (wrong extension?)")
        if is_fm_table(path):  # Δf(z, V) maps are not traces: afmlearn.fm reads them
            raise RecordingError(f"{path}: neither a table of the column convention nor a "
                                 "force curve but an FM frequency-shift table Δf(z, V): "
                                 f"`python scripts/analyze_fm.py data={path}` "
                                 "(afmlearn.fm.read_fm_spectroscopy)")
        return READERS[3] if is_convention_csv(path) else READERS[4]
    for reader in READERS:
        if suffix in reader.suffixes:
            return reader
    known = sorted({s for r in READERS for s in r.suffixes})
    raise RecordingError(f"{path}: unknown file format {suffix or '(no suffix)'!r}; "
                         f"readable: {', '.join(known)}")


def is_instrument_file(path: str | os.PathLike[str]) -> bool:
    """True for a suffix an instrument reader claims other than HDF5 (``.h5`` files are
    afmlearn traces unless converted explicitly)."""
    suffix = _suffix(Path(path))
    return suffix not in (".h5", ".hdf5") and any(suffix in r.suffixes for r in READERS)


def open_recording(path: str | os.PathLike[str], *, calibration: Any = None,
                   defaults: Mapping[str, Any] | None = None,
                   **overrides: Any) -> Trace | ForceCurve | list[Trace | ForceCurve]:
    """Open an instrument file as a `Trace` (dynamic records, lock-in curves) or a
    `ForceCurve` (static curves); a list for files holding several curves.

    Parameters
    ----------
    path : str or os.PathLike
        ``.ibw`` (Asylum), ``.jpk-force`` and other afmformats formats, ``.csv`` / ``.npz``
        / plain ``.h5`` by the column convention of docs/recordings.md. (``.nid`` thermal
        tunes hold spectra: `afmlearn.calibrate.read_spectrum`.)
    calibration : str, os.PathLike or dict, optional
        calibration.json from scripts/calibrate.py (or a dict of trace-format fields).
    defaults : dict, optional
        Trace-format fields used only where the file and calibration.json say nothing (a
        script's placeholders never replace what the file states).
    **overrides
        Trace-format fields in SI units (``spring_constant_n_per_m=2.7``, ``gap_m=5e-9``
        ...), which win over calibration.json and the file; reading options ``column``,
        ``unit``, ``invols_m_per_v``.

    Raises
    ------
    RecordingError
        One line: unknown format, damaged file, missing calibration (naming the field and how
        to supply it), wrong units.
    """
    return reader_for(path).open(path, calibration=calibration, defaults=defaults, **overrides)


def open_traces(path: str | os.PathLike[str], *, calibration: Any = None,
                **overrides: Any) -> list[Trace]:
    """`open_recording` for entry points that need traces: the file's `Trace` objects.

    Raises
    ------
    RecordingError
        Also when the file holds static force curves (no drive: not a trace).
    """
    try:
        opened = open_recording(path, calibration=calibration, **overrides)
    except MissingCalibration as err:
        if calibration is not None or overrides:
            raise
        # read as a trace= of an entry point, which passes no calibration: say how to add it
        extra = (" (or calibration=calibration.json)" if err.field in THERMAL_FIELDS else "")
        raise MissingCalibration(
            f"{path}: missing calibration '{err.field}' (not in the file): convert it with the "
            f"value first, `python scripts/convert.py input={path} output=trace.h5 "
            f"{err.field}=VALUE`{extra}, then use trace=trace.h5", field=err.field) from None
    records = opened if isinstance(opened, list) else [opened]
    if not all(isinstance(r, Trace) for r in records):
        raise RecordingError(f"{path}: a static force curve (no drive) is not a trace: analyse "
                             f"it with `python scripts/analyze_force_curve.py curve={path}` "
                             "(afmlearn.forcecurve.analyse_curve) or convert it with "
                             "scripts/convert.py")
    return records


def open_trace(path: str | os.PathLike[str], *, calibration: Any = None,
               **overrides: Any) -> Trace:
    """The one `Trace` of an instrument file (`RecordingError` for several or none)."""
    records = open_traces(path, calibration=calibration, **overrides)
    if len(records) != 1:
        raise RecordingError(f"{path}: holds {len(records)} curves; open it as an experiment "
                             "(afmlearn.io.Experiment.read) or convert one")
    return records[0]
