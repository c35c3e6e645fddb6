"""Static force curves of the formats afmformats reads (JPK ``.jpk-force``/maps/QI, AFM
Workshop ``.csv``, NT-MDT / Chiaro text, ``.tab``), as `ForceCurve` objects.

afmformats already brings every format to one convention: ``force`` [N] (> 0 repulsive),
``height (piezo)`` / ``height (measured)`` [m] decreasing towards the sample, ``segment``
0 approach / 1 retract (curves with a dwell number it 0, 1, 2 ...: the last is the retraction,
the dwell is kept with the approach), metadata ``spring constant`` [N/m], ``sensitivity`` [m/V],
``rate approach`` [Hz]. So ``z_piezo_m`` = the height (larger = further from the sample) and
``deflection_m = -force / k`` when k is known.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, final

import numpy as np

from afmlearn.io.instruments.base import InstrumentReader, Parsed
from afmlearn.io.instruments.errors import RecordingError
from afmlearn.io.instruments.units import check_length

__all__ = ["AfmformatsReader"]


@final
class AfmformatsReader(InstrumentReader):
    """Static force curves through ``afmformats.load_data`` (one `ForceCurve` per curve)."""

    suffixes = (".jpk-force", ".jpk-force-map", ".jpk-qi-data", ".jpk-qi-series", ".tab",
                ".txt", ".csv")
    name = "a force-curve file (afmformats)"

    def _parse(self, path: Path, options: Mapping[str, Any]) -> list[Parsed]:
        import afmformats

        try:
            curves = afmformats.load_data(str(path))
        except afmformats.errors.MissingMetaDataError as err:
            keys = ", ".join(map(str, getattr(err, "meta_keys", []) or ["?"]))
            hint = (": an uncalibrated curve has no force channel; calibrate the deflection "
                    "(sensitivity, spring constant) in the vendor software and export again"
                    if "spring constant" in keys or "sensitivity" in keys else "")
            raise RecordingError(f"{path}: the file does not state {keys}{hint}") from None
        except afmformats.errors.FileFormatNotSupportedError:
            if path.suffix.lower() in (".csv", ".txt"):
                raise RecordingError(
                    f"{path}: neither a table of the column convention (a header of "
                    "<quantity>_<unit> names, docs/recordings.md) nor a force-curve file "
                    "afmformats knows") from None
            raise
        out = []
        for data in curves:
            columns = list(data.columns)
            if "force" not in columns:
                raise RecordingError(f"{path}: no force column (columns {columns})")
            height = next((c for c in ("height (piezo)", "height (measured)")
                           if c in columns), None)
            if height is None:
                raise RecordingError(f"{path}: no piezo height column (columns {columns})")
            meta = data.metadata
            arrays = {"force_n": np.asarray(data["force"], dtype=float),
                      "z_piezo_m": np.asarray(data[height], dtype=float),
                      "segment": _approach_retract(np.asarray(data["segment"]))
                      if "segment" in columns else np.zeros(len(data["force"]), np.int8)}
            if "time" in columns:
                arrays["time_s"] = np.asarray(data["time"], dtype=float)
            check_length("z_piezo_m", arrays["z_piezo_m"], path)
            if not np.all(np.isfinite(arrays["force_n"])):
                raise RecordingError(f"{path}: force holds NaN or infinite values")
            header: dict[str, Any] = {"description": f"{meta.get('format', 'force curve')} "
                                                     f"{path.name}"}
            for key, name in (("spring constant", "spring_constant_n_per_m"),
                              ("sensitivity", "invols_m_per_v"),
                              ("rate approach", "sample_rate_hz")):
                value = _get(meta, key)
                if value is not None:
                    header[name] = value
            out.append(Parsed("force_curve", arrays, header))
        return out


def _approach_retract(segment: np.ndarray) -> np.ndarray:
    """afmformats numbers a curve's segments 0, 1, 2 ... (a JPK creep-compliance curve:
    extend, pause, retract; stress relaxation: four); the last is the retraction (1), every
    earlier one, a dwell included, goes with the approach (0), as an Asylum dwell does."""
    segment = segment.astype(np.int64)
    if segment.size == 0 or segment.max() <= 1:
        return segment.astype(np.int8)
    return (segment == segment.max()).astype(np.int8)


def _get(meta: Any, key: str) -> float | None:
    try:
        value = meta.get(key)
    except Exception:  # afmformats raises its own MetaDataMissingError for absent keys
        return None
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) and value > 0 else None
