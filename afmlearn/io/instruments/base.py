"""`InstrumentReader`: one reader per file format, all building the same objects.

A reader parses its format into a `Parsed` record (one abstract hook, `_parse`): the header
values it found (trace-format names, SI units), the arrays (SI units, the trace format's sign
conventions) and what they are. `InstrumentReader.open` then merges the header with
calibration.json and explicit overrides and builds a `Trace` (dynamic records and lock-in
curves) or a `ForceCurve` (static curves); any failure becomes one `RecordingError` line.
"""

from __future__ import annotations

import logging
import os
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, final

import numpy as np

from afmlearn.io.instruments.calibration import CALIBRATION_FIELDS, merge_calibration, require
from afmlearn.io.instruments.errors import RecordingError
from afmlearn.io.instruments.force_curve import ForceCurve
from afmlearn.io.trace import Trace

__all__ = ["READ_OPTIONS", "InstrumentReader", "Parsed"]

#: Overrides that steer reading rather than calibrate (column / dataset name and its unit).
READ_OPTIONS: tuple[str, ...] = ("column", "unit", "invols_m_per_v")

_PARSER_LOGGERS = ("igor2", "afmformats", "NSFopen", "jprops", "h5py")
Kind = Literal["deflection", "lockin", "force_curve", "spectrum"]
_TRACE_REQUIRED = ("sample_rate_hz", "spring_constant_n_per_m", "quality_factor",
                   "resonance_frequency_hz", "drive_frequency_hz")


@final
@dataclass(frozen=True)
class Parsed:
    """What a reader found in a file.

    Attributes
    ----------
    kind : {"deflection", "lockin", "force_curve", "spectrum"}
        A deflection time series, lock-in amplitude/phase curves, a static force curve, or a
        spectrum (not a trace: see scripts/calibrate.py).
    arrays : dict of str -> ndarray
        SI arrays under the trace format's names (``deflection_m``, ``amplitude_m``,
        ``phase_rad``, ``z_piezo_m``, ``segment``, ``gap_m``, ``force_n``, ``time_s``).
    header : dict of str -> Any
        Calibration found in the file, trace-format names and SI units.
    extra : dict of str -> Any
        Other channels and notes kept for the user (e.g. bimodal ``amplitude2_m``).
    """

    kind: Kind
    arrays: dict[str, np.ndarray]
    header: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)


class InstrumentReader(ABC):
    """Reader of one file format (hook: `_parse`)."""

    #: lower-case file suffixes this reader claims (with the dot)
    suffixes: tuple[str, ...] = ()
    #: short format name for messages
    name: str = "instrument"

    @abstractmethod
    def _parse(self, path: Path, options: Mapping[str, Any]) -> Parsed | list[Parsed]:
        """Parse ``path`` (a list for multi-curve files); raise `RecordingError` (or any
        exception, turned into one line)."""

    def parse(self, path: str | os.PathLike[str], **options: Any) -> list[Parsed]:
        """`_parse` with the file checks and the one-line error contract (always a list)."""
        path = Path(path)
        if not path.is_file():
            raise RecordingError(f"{path}: no such file")
        if path.stat().st_size == 0:
            raise RecordingError(f"{path}: empty file")
        try:
            with _quiet_parsers():
                parsed = self._parse(path, options)
            parsed = parsed if isinstance(parsed, list) else [parsed]
            if not parsed:
                raise RecordingError(f"{path}: no curve or record found")
            return parsed
        except (RecordingError, KeyboardInterrupt, SystemExit, GeneratorExit):
            raise
        except BaseException as err:  # parsers raise anything on damaged files (afmformats'
            # MetaDataMissingError derives from BaseException)
            reason = str(err).strip().splitlines()[0][:160] if str(err).strip() else ""
            raise RecordingError(
                f"{path}: cannot be read as {self.name} (truncated or corrupted?): "
                f"{type(err).__name__}{': ' + reason if reason else ''}") from None

    def open(self, path: str | os.PathLike[str], *, calibration: Any = None,
             defaults: Mapping[str, Any] | None = None,
             **overrides: Any) -> Trace | ForceCurve | list[Trace | ForceCurve]:
        """Read ``path`` into a `Trace` or a `ForceCurve` (a list of them for a multi-curve
        file), calibration merged in.

        Parameters
        ----------
        path : str or os.PathLike
            The instrument file.
        calibration : str, os.PathLike or dict, optional
            A calibration.json (scripts/calibrate.py) or a dict of trace-format fields.
        defaults : dict, optional
            Trace-format fields used only where the file (and calibration.json) says nothing,
            e.g. a script's placeholders, which must never replace what a file states.
        **overrides
            Trace-format fields (SI units) that replace the file's and calibration.json's
            values, and reading options (`READ_OPTIONS`).
        """
        path = Path(path)
        unknown = (set(overrides) - set(CALIBRATION_FIELDS) - set(READ_OPTIONS)) \
            | (set(defaults or {}) - set(CALIBRATION_FIELDS))
        if unknown:
            raise RecordingError(f"unknown override(s) {sorted(unknown)}; allowed: "
                                 f"{sorted(CALIBRATION_FIELDS + READ_OPTIONS)}")
        options = {k: v for k, v in overrides.items() if k in READ_OPTIONS}
        given = {k: v for k, v in overrides.items() if k in CALIBRATION_FIELDS}
        records = [self._build(p, merge_calibration({**(defaults or {}), **p.header},
                                                    calibration, given), path)
                   for p in self.parse(path, **options)]
        return records[0] if len(records) == 1 else records

    @staticmethod
    def _build(parsed: Parsed, values: dict[str, Any], path: Path) -> Trace | ForceCurve:
        try:
            if parsed.kind == "spectrum":
                raise RecordingError(f"{path}: holds a thermal spectrum, not a trace: "
                                     "use scripts/calibrate.py spectrum=PATH")
            if parsed.kind == "force_curve":
                return _force_curve(parsed, values, path)
            return _trace(parsed, values, path)
        except RecordingError:
            raise
        except ValueError as err:
            raise RecordingError(f"{path}: {err}") from None


@contextmanager
def _quiet_parsers() -> Iterator[None]:
    """Silence the parsers' own loggers (igor2 logs a damaged wave's raw bytes at ERROR
    level): the caller gets one `RecordingError` line instead."""
    loggers = [logging.getLogger(name) for name in _PARSER_LOGGERS]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _trace(parsed: Parsed, values: dict[str, Any], path: Path) -> Trace:
    arrays = dict(parsed.arrays)
    if parsed.kind == "lockin" and "gap_m" not in values and "gap_m" not in arrays:
        z = arrays["z_piezo_m"]
        arrays["gap_m"] = z - float(np.min(z))  # rest gap up to an unknown offset
        note = ("gap_m = z_piezo_m - min(z_piezo_m): the contact offset is unknown")
        values["description"] = "; ".join(filter(None, [values.get("description"), note]))
    require(values, _TRACE_REQUIRED, path)
    if "gap_m" not in values and "gap_m" not in arrays:
        require(values, ("gap_m",), path)
    if "gap_m" in arrays and "gap_m" in values and np.ndim(values["gap_m"]) == 0:
        arrays.pop("gap_m")  # an explicit rest gap replaces the piezo-derived one
    kwargs = {name: values[name] for name in CALIBRATION_FIELDS if name in values}
    kwargs.update({k: v for k, v in arrays.items() if k != "time_s"})
    deflection = kwargs.pop("deflection_m", None)
    return Trace(deflection, **kwargs)


def _force_curve(parsed: Parsed, values: dict[str, Any], path: Path) -> ForceCurve:
    arrays = dict(parsed.arrays)
    k = values.get("spring_constant_n_per_m")
    if "force_n" not in arrays:
        if k is None:
            require(values, ("spring_constant_n_per_m",), path)
        arrays["force_n"] = -float(k) * arrays["deflection_m"]
    elif "deflection_m" not in arrays and k is not None:
        arrays["deflection_m"] = -arrays["force_n"] / float(k)
    keep = ("spring_constant_n_per_m", "sample_rate_hz", "invols_m_per_v",
            "resonance_frequency_hz", "quality_factor")
    return ForceCurve(arrays.pop("force_n"), **arrays,
                      **{n: float(values[n]) for n in keep if values.get(n) is not None},
                      description=str(values.get("description", "")))
