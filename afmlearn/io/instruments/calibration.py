"""Calibration values of a recording: file header < calibration.json < explicit overrides."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from afmlearn.io.instruments.errors import MissingCalibration, RecordingError

__all__ = ["CALIBRATION_FIELDS", "THERMAL_FIELDS", "load_calibration", "merge_calibration",
           "require"]

#: Fields a calibration.json or an override may set (the trace format's names, SI units).
CALIBRATION_FIELDS: tuple[str, ...] = (
    "sample_rate_hz", "spring_constant_n_per_m", "quality_factor", "resonance_frequency_hz",
    "drive_frequency_hz", "gap_m", "free_amplitude_m", "excitation", "dither_amplitude_m",
    "tip_radius_m", "lockin_bandwidth_hz", "drive_phase_rad", "description",
    "drive_frequency2_hz",
)


def load_calibration(calibration: str | os.PathLike[str] | Mapping[str, Any] | None
                     ) -> dict[str, Any]:
    """The calibration fields of a calibration.json (written by scripts/calibrate.py) or dict.

    Keys other than `CALIBRATION_FIELDS` (intervals, fit diagnostics) are ignored; a field
    given as ``{"value": v, ...}`` contributes ``v``.
    """
    if calibration is None:
        return {}
    if isinstance(calibration, Mapping):
        data = dict(calibration)
    else:
        path = Path(calibration)
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            raise RecordingError(f"{path}: calibration file not found") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise RecordingError(f"{path}: not a readable calibration JSON file "
                                 f"({type(err).__name__})") from None
        if not isinstance(data, dict):
            raise RecordingError(f"{path}: a calibration file must hold a JSON object")
    out = {}
    for name in CALIBRATION_FIELDS:
        value = data.get(name)
        if isinstance(value, Mapping):
            value = value.get("value")
        if value is not None:
            out[name] = value
    return out


def merge_calibration(found: Mapping[str, Any], calibration: Any,
                      overrides: Mapping[str, Any]) -> dict[str, Any]:
    """Header values, replaced by calibration.json's, replaced by explicit overrides.

    None and NaN values never replace anything (an unset override means "keep").
    """
    out: dict[str, Any] = {}
    for layer in (found, load_calibration(calibration), overrides):
        for name, value in layer.items():
            if value is None or (isinstance(value, float) and math.isnan(value)):
                continue
            out[name] = value
    return out


#: Fields a thermal calibration (scripts/calibrate.py's calibration.json) gives.
THERMAL_FIELDS: tuple[str, ...] = ("resonance_frequency_hz", "quality_factor",
                                   "spring_constant_n_per_m")


def require(values: Mapping[str, Any], names: tuple[str, ...], path: Path | str) -> None:
    """Raise one clear line naming the first missing calibration field and how to give it
    (calibration.json only for the fields a thermal calibration gives)."""
    for name in names:
        if values.get(name) is None:
            how = (f"pass {name}=VALUE or calibration=calibration.json (scripts/calibrate.py)"
                   if name in THERMAL_FIELDS else
                   f"pass {name}=VALUE or put '# {name}: VALUE' in a CSV header (a thermal "
                   "calibration does not give it)")
            raise MissingCalibration(f"{path}: missing calibration '{name}' (not in the "
                                     f"file): {how}", field=name)
