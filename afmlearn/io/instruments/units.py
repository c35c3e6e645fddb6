"""Unit suffixes of the documented column convention (docs/recordings.md) and sanity checks."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from afmlearn.io.instruments.errors import RecordingError

__all__ = ["LENGTH_LIMIT_M", "SCALE", "check_length", "split_unit"]

#: multiply a value with this unit suffix by the factor to get SI
SCALE: dict[str, float] = {
    "m": 1.0, "um": 1e-6, "nm": 1e-9, "pm": 1e-12,
    "s": 1.0, "ms": 1e-3, "us": 1e-6,
    "n": 1.0, "nn": 1e-9, "pn": 1e-12,
    "rad": 1.0, "deg": math.pi / 180.0,
    "hz": 1.0, "khz": 1e3,
    "v": 1.0,
}
#: no deflection, amplitude or piezo travel of an AFM reaches this (a sanity bound)
LENGTH_LIMIT_M = 1e-3


def split_unit(column: str) -> tuple[str, str] | None:
    """``"deflection_nm"`` -> ``("deflection", "nm")``; None without a known unit suffix."""
    stem, _, unit = column.strip().lower().rpartition("_")
    return (stem, unit) if stem and unit in SCALE else None


def check_length(name: str, values: NDArray[np.float64], path: object) -> None:
    """Raise one line if lengths [m] are not finite or too large to be metres."""
    if values.size == 0:
        raise RecordingError(f"{path}: '{name}' is empty")
    if not np.all(np.isfinite(values)):
        raise RecordingError(f"{path}: '{name}' holds NaN or infinite values")
    peak = float(np.max(np.abs(values)))
    if peak > LENGTH_LIMIT_M:
        raise RecordingError(
            f"{path}: '{name}' reaches {peak:.3g} m, not a length an AFM records in metres "
            "(wrong units? name the column with its unit, e.g. deflection_nm, or pass the "
            "unit override)")
