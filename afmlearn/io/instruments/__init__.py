"""Instrument files in: one reader per format, all building `Trace` or `ForceCurve` objects.

Public API
----------
`open_recording`, `open_trace`, `open_traces`
    Open an instrument file (Asylum ``.ibw``, JPK and the other afmformats formats, CSV /
    NPZ / plain HDF5 by the column convention of docs/recordings.md) with calibration.
`ForceCurve`, `write_force_curve`, `read_force_curve`
    A static force curve (no drive) and its HDF5 file.
`convert_recording`
    Instrument file -> trace format v1 (or a force-curve file): what scripts/convert.py does.
`RecordingError`
    The one-line error for unknown, damaged or uncalibrated files.
`READERS`, `reader_for`, `is_instrument_file`, `InstrumentReader`, `Parsed`
    The registry and the reader interface (adding a format is one reader class).
`load_calibration`, `CALIBRATION_FIELDS`
    calibration.json (scripts/calibrate.py) as trace-format fields.
"""

from afmlearn.io.instruments.base import READ_OPTIONS, InstrumentReader, Parsed
from afmlearn.io.instruments.calibration import CALIBRATION_FIELDS, load_calibration
from afmlearn.io.instruments.convert import convert_recording
from afmlearn.io.instruments.errors import RecordingError
from afmlearn.io.instruments.force_curve import ForceCurve, read_force_curve, write_force_curve
from afmlearn.io.instruments.registry import (
    READERS,
    is_instrument_file,
    open_recording,
    open_trace,
    open_traces,
    reader_for,
)

__all__ = [
    "CALIBRATION_FIELDS",
    "READERS",
    "READ_OPTIONS",
    "ForceCurve",
    "InstrumentReader",
    "Parsed",
    "RecordingError",
    "convert_recording",
    "is_instrument_file",
    "load_calibration",
    "open_recording",
    "open_trace",
    "open_traces",
    "read_force_curve",
    "reader_for",
    "write_force_curve",
]
