"""FM-AFM frequency-shift spectroscopy tables: Δf versus piezo position and tip bias.

Two CSV layouts are read (both those of the nc_AFM example data, phys201/nc_AFM):

* a **map**: header ``,<bias 1>,<bias 2>,...`` [V], then one row per piezo position whose
  first cell is a row index and the rest Δf [Hz]; the piezo positions [m] come from a
  one-column file (``z_piezo.csv``) next to it, one value per map row;
* a **column table**: header ``z,<bias 1>,...``: the first column holds the piezo position [m]
  itself (e.g. ``all_data_dataframe_237K.csv``, Δf(z) at six biases).

The calibration is not in these files: the spring constant, oscillation amplitude and free
resonance frequency come from a sidecar ``fm_calibration.json`` in the same folder (keys
:data:`FM_FIELDS`) and/or explicit keyword overrides (which win). Signs: ``z_piezo_m`` larger
= further from the sample (the trace format's convention; in the example data Δf turns
strongly positive, i.e. repulsive, at the smallest ``z``); Δf > 0 is a stiffer effective
spring (a repulsive force gradient, ``physics.md`` section 1: ``F > 0`` repulsive).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io.instruments.errors import MissingCalibration, RecordingError
from afmlearn.io.instruments.table import csv_delimiter, split_cells

__all__ = ["FM_FIELDS", "FMSpectroscopy", "is_fm_table", "read_fm_spectroscopy"]

#: calibration fields of an FM spectroscopy (SI units), sidecar / override names
FM_FIELDS: tuple[str, ...] = ("spring_constant_n_per_m", "amplitude_m", "resonance_frequency_hz")
#: sidecar file with the calibration, looked up next to the table
SIDECAR = "fm_calibration.json"
_Z_FILE = "z_piezo.csv"
_MAP_GLOB = "df_dataframe*.csv"
_RANGES = {"spring_constant_n_per_m": (1e-3, 1e6), "amplitude_m": (1e-12, 1e-6),
           "resonance_frequency_hz": (1.0, 1e8)}


@final
@dataclass(frozen=True)
class FMSpectroscopy:
    """A frequency-shift map Δf(z, V) of one tip, SI units.

    Attributes
    ----------
    frequency_shift_hz : ndarray, shape (n_z, n_bias)
        Δf [Hz] at piezo position ``z_piezo_m[i]`` and tip bias ``bias_v[j]``.
    z_piezo_m : ndarray, shape (n_z,)
        Piezo position [m], larger = further from the sample, strictly monotonic.
    bias_v : ndarray, shape (n_bias,)
        Tip--sample bias [V] of each column (distinct).
    spring_constant_n_per_m : float
        Lever (tuning-fork prong) stiffness k [N/m].
    amplitude_m : float
        Oscillation amplitude A [m] (zero to peak).
    resonance_frequency_hz : float
        Free resonance f0 [Hz].
    source : str
        Where the map came from (path).
    """

    frequency_shift_hz: NDArray[np.float64]
    z_piezo_m: NDArray[np.float64]
    bias_v: NDArray[np.float64]
    spring_constant_n_per_m: float
    amplitude_m: float
    resonance_frequency_hz: float
    source: str = ""

    def __post_init__(self) -> None:
        df = np.asarray(self.frequency_shift_hz, float)
        z = np.asarray(self.z_piezo_m, float)
        v = np.asarray(self.bias_v, float)
        if df.ndim != 2 or df.shape != (z.size, v.size):
            raise ValueError(f"frequency_shift_hz: shape {df.shape} does not match "
                             f"(n_z, n_bias) = ({z.size}, {v.size})")
        if z.size < 3 or not np.all(np.isfinite(z)):
            raise ValueError("z_piezo_m: needs >= 3 finite positions")
        dz = np.diff(z)
        if not (np.all(dz > 0) or np.all(dz < 0)):
            raise ValueError("z_piezo_m: positions must be strictly monotonic")
        if np.unique(v).size != v.size or not np.all(np.isfinite(v)):
            raise ValueError("bias_v: biases must be finite and distinct")
        if not np.all(np.isfinite(df)):
            raise ValueError("frequency_shift_hz: holds NaN or infinite values")
        for name in FM_FIELDS:
            value = float(getattr(self, name))
            low, high = _RANGES[name]
            if not (math.isfinite(value) and low <= value <= high):
                raise ValueError(f"{name}: {value!r} outside the allowed range [{low}, {high}]")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "frequency_shift_hz", df)
        object.__setattr__(self, "z_piezo_m", z)
        object.__setattr__(self, "bias_v", v)

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_z, n_bias)``."""
        return self.frequency_shift_hz.shape  # type: ignore[return-value]

    def rows(self, index: NDArray[np.int64] | slice) -> FMSpectroscopy:
        """The same map restricted to the piezo positions ``index``."""
        return FMSpectroscopy(self.frequency_shift_hz[index], self.z_piezo_m[index],
                              self.bias_v, self.spring_constant_n_per_m, self.amplitude_m,
                              self.resonance_frequency_hz, self.source)

    def columns(self, index: NDArray[np.int64] | slice) -> FMSpectroscopy:
        """The same map restricted to the bias columns ``index``."""
        return FMSpectroscopy(self.frequency_shift_hz[:, index], self.z_piezo_m,
                              self.bias_v[index], self.spring_constant_n_per_m,
                              self.amplitude_m, self.resonance_frequency_hz, self.source)


def _rows(path: Path) -> list[list[str]]:
    """Non-blank lines of a text table as cells, in the dialects of the CSV reader
    (:func:`~afmlearn.io.instruments.table.csv_delimiter`: ``,``, or ``;``/tab with decimal
    commas; a byte-order mark; quoted cells)."""
    try:
        text = path.read_text(encoding="utf-8-sig", errors="strict")
    except (OSError, UnicodeDecodeError) as err:
        raise RecordingError(f"{path}: cannot read as a text CSV ({type(err).__name__})") from None
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines:
        raise RecordingError(f"{path}: empty file")
    sep = csv_delimiter(lines[0])
    return [_cells(line, sep) for line in lines]


def _cells(line: str, sep: str) -> list[str]:
    cells = [c.strip('"').strip("'") for c in split_cells(line, sep)]
    # "1,5;2,0": a decimal comma (a comma never separates here)
    return cells if sep == "," else [c.replace(",", ".") for c in cells]


def _numbers(cells: list[str], path: Path, what: str) -> NDArray[np.float64]:
    try:
        out = np.array([float(c) for c in cells], float)
    except ValueError:
        bad = next(c for c in cells if not _is_float(c))
        raise RecordingError(f"{path}: non-numeric {what} {bad[:20]!r}") from None
    if not np.all(np.isfinite(out)):
        raise RecordingError(f"{path}: {what} holds NaN or infinite values")
    return out


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def is_fm_table(path: str | os.PathLike[str]) -> bool:
    """True for a folder holding a Δf map + ``z_piezo.csv``, or a CSV whose header is a row of
    biases (first cell empty or ``z``, all others numbers)."""
    path = Path(path)
    if path.is_dir():
        return bool(sorted(path.glob(_MAP_GLOB))) and (path / _Z_FILE).is_file()
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    try:
        with path.open("r", encoding="utf-8-sig", errors="strict") as f:
            line = next((x for x in f if x.strip()), "")
    except (OSError, UnicodeDecodeError):
        return False
    head = _cells(line, csv_delimiter(line))
    return (len(head) >= 2 and head[0].strip().lower() in ("", "z")
            and all(_is_float(c) for c in head[1:]))


def _calibration(folder: Path, overrides: dict[str, Any], source: Path) -> dict[str, float]:
    values: dict[str, Any] = {}
    sidecar = folder / SIDECAR
    if sidecar.is_file():
        try:
            values.update(json.loads(sidecar.read_text()))
        except (OSError, ValueError) as err:
            raise RecordingError(f"{sidecar}: not a JSON object ({type(err).__name__})") from None
    values.update({k: v for k, v in overrides.items() if v is not None})
    unknown = sorted(set(overrides) - set(FM_FIELDS))
    if unknown:
        raise ValueError(f"overrides: unknown field(s) {unknown}; allowed: {list(FM_FIELDS)}")
    out = {}
    for name in FM_FIELDS:
        if values.get(name) is None:
            raise MissingCalibration(
                f"{source}: missing calibration '{name}' (FM tables do not hold it): pass "
                f"{name}=VALUE or put it in {SIDECAR} next to the table", field=name)
        try:
            out[name] = float(values[name])
        except (TypeError, ValueError):
            raise ValueError(f"{name}: not a number: {values[name]!r}") from None
    return out


def read_fm_spectroscopy(path: str | os.PathLike[str], *, z_file: str | os.PathLike[str] | None
                         = None, **overrides: Any) -> FMSpectroscopy:
    """Read a Δf(z, V) table into an :class:`FMSpectroscopy`.

    Parameters
    ----------
    path : str or os.PathLike
        A folder (the map ``df_dataframe*.csv`` and ``z_piezo.csv`` in it) or one CSV (a map,
        with ``z_piezo.csv`` beside it or ``z_file``; or a column table with a ``z`` column).
    z_file : str or os.PathLike, optional
        The piezo positions [m] of a map's rows (default ``z_piezo.csv`` beside the map).
    **overrides
        Calibration (:data:`FM_FIELDS`, SI units); wins over the sidecar ``fm_calibration.json``.

    Raises
    ------
    RecordingError
        (a ValueError) one line: missing file or calibration, truncated or non-numeric table,
        row count of the map and the z file differ, out-of-range calibration.
    """
    path = Path(path)
    if path.is_dir():
        maps = sorted(path.glob(_MAP_GLOB))
        if not maps:
            raise RecordingError(f"{path}: no Δf map ({_MAP_GLOB}) in the folder")
        path = maps[0]
    if not path.is_file():
        raise RecordingError(f"{path}: no such file")
    rows = _rows(path)
    head = [c.strip() for c in rows[0]]
    if len(head) < 2 or head[0].lower() not in ("", "z"):
        raise RecordingError(f"{path}: not an FM table (header must be ',<bias>,...' or "
                             "'z,<bias>,...')")
    bias = _numbers(head[1:], path, "bias in the header")
    body = rows[1:]
    if len(body) < 3:
        raise RecordingError(f"{path}: only {len(body)} data rows (truncated?)")
    short = [i for i, r in enumerate(body) if len(r) != len(head)]
    if short:
        raise RecordingError(f"{path}: row {short[0] + 2} has {len(body[short[0]])} cells, "
                             f"header has {len(head)} (truncated or damaged)")
    table = np.vstack([_numbers(r, path, f"cell in row {i + 2}") for i, r in enumerate(body)])
    df = table[:, 1:]
    if head[0].lower() == "z":
        z = table[:, 0]
    else:
        zpath = Path(z_file) if z_file is not None else path.parent / _Z_FILE
        if not zpath.is_file():
            raise RecordingError(f"{path}: the map's piezo positions {zpath} are missing "
                                 "(pass z_file=...)")
        zrows = _rows(zpath)
        if any(len(r) != 1 for r in zrows):
            raise RecordingError(f"{zpath}: expected one column of positions [m]")
        z = _numbers([r[0] for r in zrows], zpath, "position")
        if z.size != df.shape[0]:
            raise RecordingError(f"{path}: {df.shape[0]} map rows but {z.size} positions in "
                                 f"{zpath.name} (shape mismatch)")
    if np.max(np.abs(z)) > 1e-3:
        raise RecordingError(f"{path}: piezo positions up to {np.max(np.abs(z)):.3g} are not "
                             "metres")
    calib = _calibration(path.parent, overrides, path)
    try:
        return FMSpectroscopy(df, z, bias, source=str(path), **calib)
    except ValueError as err:
        raise RecordingError(f"{path}: {err}") from None
