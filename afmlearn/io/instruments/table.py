"""Plain tables of a recording: CSV, NPZ and plain HDF5, with one documented column convention.

Columns (CSV header names, NPZ array names, HDF5 dataset names) are ``<quantity>_<unit>``:
quantities ``time``, ``deflection``, ``amplitude``, ``phase``, ``z_piezo``, ``gap``, ``force``
and ``segment`` (no unit; 0 approach, 1 retraction); units as in `units.SCALE` (``m``,
``um``, ``nm``, ``pm``; ``s``, ``ms``, ``us``; ``n``, ``nn``, ``pn``; ``rad``, ``deg``; ``v``
for a deflection in volts, converted with ``invols_m_per_v``). Signs as in the trace format:
deflection towards the sample positive, ``z_piezo`` larger = further from the sample, force
> 0 repulsive, phase = lag of the deflection behind the drive.

What the table is follows from its columns: ``force_*`` -> a static `ForceCurve`;
``amplitude_*`` and ``phase_*`` -> lock-in curves; otherwise ``deflection_*`` -> a deflection
time series (a ramp when ``gap_*`` is given). Calibration: CSV lines ``# name: value`` before
the header, NPZ 0-d arrays, HDF5 root attributes, all with the trace format's names in SI
units (``sample_rate_hz``, ``spring_constant_n_per_m`` ...); the sample rate may also come
from a ``time_*`` column. A dataset named otherwise (e.g. an HDF5 dataset ``s``) is taken as
the deflection with the overrides ``column=NAME unit=UNIT``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, final

import numpy as np

from afmlearn.io.instruments.base import InstrumentReader, Parsed
from afmlearn.io.instruments.calibration import CALIBRATION_FIELDS
from afmlearn.io.instruments.errors import RecordingError
from afmlearn.io.instruments.units import SCALE, check_length, split_unit

__all__ = ["CsvReader", "Hdf5SeriesReader", "NpzReader", "is_convention_csv"]

_QUANTITIES = {"time": "time_s", "deflection": "deflection_m", "amplitude": "amplitude_m",
               "phase": "phase_rad", "z_piezo": "z_piezo_m", "gap": "gap_m", "force": "force_n",
               "amplitude2": "amplitude2_m", "phase2": "phase2_rad"}
_LENGTHS = ("deflection_m", "amplitude_m", "z_piezo_m", "gap_m", "amplitude2_m")
_HEADER_NUMBERS = tuple(f for f in CALIBRATION_FIELDS if f not in ("excitation", "description"))


@final
class CsvReader(InstrumentReader):
    """CSV with the column convention (``#`` metadata lines, one header line)."""

    suffixes = (".csv",)
    name = "a CSV table (docs/recordings.md convention)"

    def _parse(self, path: Path, options: Mapping[str, Any]) -> Parsed:
        meta: dict[str, Any] = {}
        header_line, n_lines = None, 0
        # utf-8-sig: spreadsheet exports start with a byte-order mark
        lines = path.read_text(encoding="utf-8-sig", errors="strict").splitlines()
        for line in lines:
            n_lines += 1
            stripped = line.strip()
            if stripped.startswith("#"):
                key, sep, value = stripped[1:].partition(":")
                if sep:
                    meta[key.strip()] = value.strip()
                continue
            if stripped:
                header_line = stripped
                break
        if header_line is None:
            raise RecordingError(f"{path}: no header line with column names")
        delimiter = csv_delimiter(header_line)
        names = [_column_name(c) for c in split_cells(header_line, delimiter)]
        rows = [line for line in lines[n_lines:] if line.strip()
                and not line.lstrip().startswith("#")]
        if delimiter != ",":  # "1,5;2,0": a decimal comma (a comma never separates here)
            rows = [line.replace(",", ".") for line in rows]
        if delimiter != " ":  # a trailing separator ("1;2;") ends no column
            rows = [line.rstrip().removesuffix(delimiter) for line in rows]
        if not rows:
            raise RecordingError(f"{path}: no rows of numbers after the header line")
        try:
            table = np.loadtxt(rows, delimiter=None if delimiter == " " else delimiter,
                               ndmin=2)
        except ValueError as err:
            raise RecordingError(f"{path}: not a numeric table after the header line "
                                 f"({str(err).splitlines()[0][:100]})") from None
        if table.shape[1] != len(names):
            raise RecordingError(f"{path}: {len(names)} column names but {table.shape[1]} "
                                 "columns of numbers")
        return from_columns({n: table[:, i] for i, n in enumerate(names)}, meta, path, options)


@final
class NpzReader(InstrumentReader):
    """NumPy ``.npz`` with the column convention (0-d arrays hold the calibration)."""

    suffixes = (".npz",)
    name = "a NumPy .npz archive"

    def _parse(self, path: Path, options: Mapping[str, Any]) -> Parsed:
        with np.load(path, allow_pickle=False) as npz:
            items = {k: npz[k] for k in npz.files}
        columns = {k: v for k, v in items.items() if np.ndim(v) == 1}
        meta = {k: v.item() for k, v in items.items() if np.ndim(v) == 0}
        return from_columns(columns, meta, path, options)


@final
class Hdf5SeriesReader(InstrumentReader):
    """Plain HDF5 (not an afmlearn trace file): 1-D datasets by the column convention, root
    attributes as calibration; ``column=NAME unit=UNIT`` names a deflection dataset."""

    suffixes = (".h5", ".hdf5")
    name = "a plain HDF5 file"

    def _parse(self, path: Path, options: Mapping[str, Any]) -> Parsed:
        import h5py

        with h5py.File(path, "r") as f:
            if f.attrs.get("format") in ("afmlearn-trace", b"afmlearn-trace"):
                raise RecordingError(f"{path}: already an afmlearn trace file "
                                     "(read it with afmlearn.io.read_trace)")
            columns = {k: v[()] for k, v in f.items()
                       if isinstance(v, h5py.Dataset) and v.ndim == 1}
            meta = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
        return from_columns(columns, meta, path, options)


def from_columns(columns: Mapping[str, np.ndarray], meta: Mapping[str, Any], path: Path,
                 options: Mapping[str, Any]) -> Parsed:
    """Map convention-named columns to SI arrays and choose what the record is."""
    arrays: dict[str, np.ndarray] = {}
    invols = options.get("invols_m_per_v", meta.get("invols_m_per_v"))
    chosen = options.get("column")
    if chosen is not None:
        if chosen not in columns:
            raise RecordingError(f"{path}: no column or dataset {chosen!r} "
                                 f"(found {sorted(columns)})")
        unit = str(options.get("unit", "")).lower()
        if unit not in SCALE:
            raise RecordingError(f"{path}: unit={options.get('unit')!r} for column {chosen!r}: "
                                 f"give one of {sorted(SCALE)}")
        columns = {**{k: v for k, v in columns.items() if k != chosen},
                   f"deflection_{unit}": columns[chosen]}
    for name, values in columns.items():
        if name.strip().lower() == "segment":
            arrays["segment"] = np.asarray(values)
            continue
        parts = split_unit(name)
        if parts is None or parts[0] not in _QUANTITIES:
            continue
        quantity, unit = parts
        values = np.asarray(values, dtype=float)
        target = _QUANTITIES[quantity]
        if unit == "v":
            if quantity != "deflection":
                raise RecordingError(f"{path}: volts are accepted for the deflection only")
            if invols is None:
                raise RecordingError(f"{path}: column {name!r} is in volts: pass "
                                     "invols_m_per_v=VALUE (optical-lever sensitivity, m/V)")
            arrays[target] = values * float(invols)
            continue
        if _unit_kind(unit) != _unit_kind(target.rpartition("_")[2]):
            raise RecordingError(f"{path}: column {name!r}: unit {unit!r} does not fit "
                                 f"{quantity} (wants {target.rpartition('_')[2]})")
        arrays[target] = values * SCALE[unit]
    if not arrays:
        raise RecordingError(f"{path}: no column follows the convention <quantity>_<unit> "
                             f"(found {sorted(columns)[:8]}); see docs/recordings.md, or pass "
                             "column=NAME unit=UNIT")
    for name in _LENGTHS:
        if name in arrays:
            check_length(name, arrays[name], path)
    header: dict[str, Any] = {}
    for key, value in meta.items():
        if key in _HEADER_NUMBERS:
            try:
                header[key] = float(value)
            except (TypeError, ValueError):
                raise RecordingError(f"{path}: metadata {key!r} = {value!r} is not a number")\
                    from None
        elif key in ("excitation", "description"):
            header[key] = str(value)
    time = arrays.get("time_s")
    if time is not None and "sample_rate_hz" not in header and time.size > 1:
        step = float(np.median(np.diff(time)))
        if step > 0 and math.isfinite(step):
            header["sample_rate_hz"] = 1.0 / step
    if "force_n" in arrays:
        kind = "force_curve"
        arrays.setdefault("segment", np.zeros(arrays["force_n"].size, np.int8))
        if "z_piezo_m" not in arrays:
            raise RecordingError(f"{path}: a force curve needs a z_piezo_<unit> column")
    elif "amplitude_m" in arrays and "phase_rad" in arrays:
        kind = "lockin"
    elif "deflection_m" in arrays:
        kind = "deflection"
    else:
        raise RecordingError(f"{path}: needs deflection_<unit>, amplitude_<unit> + "
                             f"phase_<unit>, or force_<unit> + z_piezo_<unit> columns; found "
                             f"{sorted(arrays)}")
    n = {a.size for k, a in arrays.items()}
    if len(n) != 1:
        raise RecordingError(f"{path}: columns of different lengths {sorted(n)}")
    if kind == "deflection":
        arrays.pop("time_s", None)
        arrays.pop("z_piezo_m", None) if "gap_m" in arrays else None
    header.setdefault("description", f"{path.name}")
    return Parsed(kind, arrays, header)


def is_convention_csv(path: Path) -> bool:
    """True when the first non-comment line of ``path`` names convention columns (separated
    by ``,``, ``;`` or tabs; ``deflection_nm``, ``deflection [nm]`` or ``deflection (nm)``)."""
    try:
        with path.open("r", encoding="utf-8-sig", errors="replace") as f:
            for line in f:
                stripped = line.strip()
                if stripped and not stripped.startswith("#"):
                    cells = split_cells(stripped, csv_delimiter(stripped))
                    names = [_column_name(c) for c in cells]
                    return all(n.lower() == "segment" or (split_unit(n) or ("",))[0]
                               in _QUANTITIES for n in names)
    except OSError:
        return False
    return False


def csv_delimiter(header: str) -> str:
    """The column separator of a CSV header line: ``;`` or a tab when present (European
    spreadsheet exports, which then write decimal commas), else ``,``; ``" "`` for names
    separated by blanks only."""
    for sep in (";", "\t", ","):
        if sep in header:
            return sep
    return " "


def split_cells(line: str, delimiter: str) -> list[str]:
    cells = line.split() if delimiter == " " else line.strip().split(delimiter)
    cells = [c.strip() for c in cells]
    return cells[:-1] if len(cells) > 1 and cells[-1] == "" else cells  # a trailing separator


_BRACKETED = re.compile(r"^(?P<q>[^\[\(]+?)\s*[\[\(]\s*(?P<u>[^\]\)]+?)\s*[\]\)]$")


def _column_name(cell: str) -> str:
    """``"deflection [nm]"``, ``"Deflection (nm)"``, ``"z piezo [µm]"``, ``"\"time_s\""``
    -> the convention's ``deflection_nm``, ``z_piezo_um``, ``time_s``; other names as given."""
    name = cell.strip().strip('"').strip("'").strip()
    match = _BRACKETED.match(name)
    if match:
        unit = match["u"].strip().lower().replace("µ", "u").replace("μ", "u")
        unit = {"°": "deg", "degree": "deg", "degrees": "deg"}.get(unit, unit)
        name = "_".join(match["q"].split()) + "_" + unit
    return name


def _unit_kind(unit: str) -> str:
    if unit in ("m", "um", "nm", "pm"):
        return "length"
    if unit in ("s", "ms", "us"):
        return "time"
    if unit in ("n", "nn", "pn"):
        return "force"
    if unit in ("rad", "deg"):
        return "angle"
    return unit
