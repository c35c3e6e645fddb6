"""Asylum Research (Igor binary wave, ``.ibw``) force and AC-mode curves, read with igor2.

Channels are found by their dimension label (columns of the 2-D wave): ``Raw`` (Z piezo
command), ``Defl`` (static deflection, m), ``Amp`` / ``Phase`` (first lock-in: m, degrees),
``Amp2`` / ``Phas2`` (bimodal second lock-in: m or V, degrees), ``ZSnsr`` (Z sensor, m).
Conventions mapped:

- ``ZSnsr`` grows as the piezo extends towards the sample (it rises during the approach, the
  segment with ``Direction`` +1): ``z_piezo_m = -ZSnsr`` (larger = further from the sample).
- ``Defl`` is positive when the lever bends away from the sample (repulsion):
  ``deflection_m = -Defl`` and ``force_n = k Defl``.
- ``Phase`` is the lock-in phase in degrees with Asylum's offset tuned so that the free
  lever reads 90 deg at resonance, > 90 deg in the attractive and < 90 deg in the repulsive
  regime; that is the lag of the deflection behind the drive (driving above the effective
  resonance, as an attractive force makes it, increases the lag): ``phase_rad =
  radians(Phase)``, the trace format's convention (pi/2 on free resonance).
- ``Indexes: 0,i1,...,n-1`` with ``Direction: NaN,1,-1`` split the curve: +1 extension
  (approach, segment 0), -1 retraction (segment 1); dwell segments (0) go with the preceding
  part.
- Wave note: ``SpringConstant`` [N/m], ``ThermalQ``, ``ThermalFrequency`` (f0 [Hz]),
  ``DriveFrequency`` [Hz], ``InvOLS`` / ``AmpInvOLS`` [m/V], ``NumPtsPerSec`` [Hz],
  ``ForceFilterBW`` [Hz] (output filter of the curve channels, taken as the lock-in bandwidth).
- Bimodal (DualAC): ``Amp2`` / ``Phas2`` become ``amplitude2_m`` / ``phase2_rad`` with the
  same conventions, at ``DriveFrequency1`` (``drive_frequency2_hz``); an ``Amp2`` stored in
  volts is scaled by ``Amp2InvOLS`` (the second mode's own sensitivity, not ``AmpInvOLS``:
  the optical lever sees each mode's slope). Without ``Amp2InvOLS`` a volt-valued ``Amp2``
  cannot be put in metres: it is left out of the trace (kept in ``extra``) with a warning.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, final

import numpy as np

from afmlearn.io.instruments.base import InstrumentReader, Parsed
from afmlearn.io.instruments.errors import RecordingError
from afmlearn.io.instruments.units import check_length

__all__ = ["AsylumReader", "parse_note"]

logger = logging.getLogger(__name__)

_NOTE_FIELDS = {  # wave-note key -> trace-format name
    "SpringConstant": "spring_constant_n_per_m",
    "ThermalQ": "quality_factor",
    "ThermalFrequency": "resonance_frequency_hz",
    "DriveFrequency": "drive_frequency_hz",
    "NumPtsPerSec": "sample_rate_hz",
    "ForceFilterBW": "lockin_bandwidth_hz",
}


@final
class AsylumReader(InstrumentReader):
    """Asylum Research ``.ibw`` curves (contact force curves and AC-mode lock-in curves)."""

    suffixes = (".ibw",)
    name = "an Asylum Igor binary wave (.ibw)"

    def _parse(self, path: Path, options: Mapping[str, Any]) -> Parsed:
        from igor2 import binarywave

        loaded = binarywave.load(str(path))
        wave = loaded["wave"]
        with np.errstate(invalid="ignore", over="ignore"):  # damaged values: checked below
            data = np.asarray(wave["wData"], dtype=float)
        note = parse_note(wave.get("note", b""))
        dim_labels = wave.get("labels") or []  # versions 1-3 have no dimension labels
        labels = [_text(b) for b in (dim_labels[1] if len(dim_labels) > 1 else [])]
        labels = labels[1:] if labels and labels[0] == "" else labels
        if data.ndim != 2 or not labels or data.shape[1] != len(labels):
            version = loaded.get("version", "?")
            name = _text(wave.get("wave_header", {}).get("bname", b""))
            raise RecordingError(
                f"{path}: Igor wave version {version} '{name}' of shape {data.shape} with column "
                f"labels {labels}: afmlearn reads Asylum curves saved as one 2-D wave (version "
                "5) whose columns are labelled Raw/ZSnsr and Defl or Amp+Phase; a single-"
                "channel wave (versions 1-3 hold only one) is not a curve")
        columns = {name: data[:, i] for i, name in enumerate(labels)}
        header = {v: note[k] for k, v in _NOTE_FIELDS.items() if _number(note.get(k))}
        if "sample_rate_hz" not in header:
            step = float(np.asarray(wave["wave_header"].get("sfA", [0.0]))[0])
            if step > 0:
                header["sample_rate_hz"] = 1.0 / step
        if _number(note.get("InvOLS")):
            header["invols_m_per_v"] = note["InvOLS"]
        header["description"] = (f"Asylum {note.get('ImagingMode', '?')} curve {path.name}, "
                                 f"{note.get('Date', '')} {note.get('Time', '')}".strip())
        z_source = "ZSnsr" if "ZSnsr" in columns else "Raw" if "Raw" in columns else None
        if z_source is None:
            raise RecordingError(f"{path}: no Z column (ZSnsr or Raw) to place the curve on; "
                                 f"labels {labels}")
        if _volts(columns[z_source]):
            raise RecordingError(f"{path}: {z_source} reaches "
                                 f"{np.nanmax(np.abs(columns[z_source])):.3g}: in volts, not "
                                 "metres (save the curve with the Z sensor in metres)")
        arrays: dict[str, np.ndarray] = {"z_piezo_m": -columns[z_source],
                                         "segment": _segments(note, data.shape[0], path)}
        check_length("z_piezo_m", arrays["z_piezo_m"], path)
        extra = {"note": note, "labels": labels}
        if "Amp" in columns and "Phase" in columns:
            amp = columns["Amp"]
            if _volts(amp):
                if not _number(note.get("AmpInvOLS")):
                    raise RecordingError(f"{path}: Amp is in volts and the wave note has no "
                                         "AmpInvOLS (amplitude sensitivity, m/V) to put it in "
                                         "metres")
                amp = amp * note["AmpInvOLS"]  # stored in volts: Amp x AmpInvOLS [m/V]
            check_length("Amp", amp, path)
            arrays.update(amplitude_m=amp, phase_rad=np.radians(columns["Phase"]))
            _bimodal(columns, note, arrays, header, extra, path)
            return Parsed("lockin", arrays, header, extra)
        if "Defl" in columns:
            defl = columns["Defl"]
            if _volts(defl):
                given = options.get("invols_m_per_v")
                invols = float(given) if given is not None else note.get("InvOLS")
                if not _number(invols):
                    raise RecordingError(f"{path}: Defl is in volts and the wave note has no "
                                         "InvOLS: pass invols_m_per_v=VALUE (deflection "
                                         "sensitivity, m/V)")
                defl = defl * float(invols)  # stored in volts
                header["invols_m_per_v"] = float(invols)
            check_length("Defl", defl, path)
            arrays["deflection_m"] = -defl
            rate = header.get("sample_rate_hz")
            if rate:
                arrays["time_s"] = np.arange(data.shape[0]) / rate
            return Parsed("force_curve", arrays, header, extra)
        raise RecordingError(f"{path}: neither Amp/Phase (AC mode) nor Defl (force curve) "
                             f"columns; labels {labels}")


def _bimodal(columns: Mapping[str, np.ndarray], note: Mapping[str, Any],
             arrays: dict[str, np.ndarray], header: dict[str, Any], extra: dict[str, Any],
             path: Path) -> None:
    """Put the second lock-in (``Amp2`` [m or V], ``Phas2`` [deg]) into ``arrays`` in SI."""
    if "Amp2" not in columns:
        if "Phas2" in columns:
            extra["phase2_rad"] = np.radians(columns["Phas2"])
        return
    amp2 = columns["Amp2"]
    if _volts(amp2):
        if not _number(note.get("Amp2InvOLS")):
            logger.warning("%s: Amp2 is in volts and the note has no Amp2InvOLS; the second "
                           "lock-in is left out of the trace (extra['amplitude2_v'])", path)
            extra["amplitude2_v"] = amp2
            if "Phas2" in columns:
                extra["phase2_rad"] = np.radians(columns["Phas2"])
            return
        amp2 = amp2 * note["Amp2InvOLS"]
    check_length("Amp2", amp2, path)
    arrays["amplitude2_m"] = amp2
    if "Phas2" in columns:
        arrays["phase2_rad"] = np.radians(columns["Phas2"])
    if _number(note.get("DriveFrequency1")):
        header["drive_frequency2_hz"] = note["DriveFrequency1"]


def parse_note(note: bytes | str) -> dict[str, Any]:
    """The ``Key: value`` lines of an Asylum wave note; numbers as float, the rest as str."""
    text = note.decode("latin-1") if isinstance(note, bytes) else str(note)
    out: dict[str, Any] = {}
    for line in text.replace("\r", "\n").split("\n"):
        key, sep, value = line.partition(":")
        if not sep or not key.strip():
            continue
        value = value.strip()
        try:
            out[key.strip()] = float(value)
        except ValueError:
            out[key.strip()] = value
    return out


def _segments(note: Mapping[str, Any], n: int, path: Path) -> np.ndarray:
    """0 approach / 1 retraction from ``Indexes`` and ``Direction``; all 0 without them."""
    segment = np.zeros(n, dtype=np.int8)
    indexes, directions = note.get("Indexes"), note.get("Direction")
    if not isinstance(indexes, str) or not isinstance(directions, str):
        return segment  # absent, or a single number: nothing to split
    try:
        idx = [int(float(v)) for v in indexes.split(",") if v.strip()]
        dirs = [float(v) for v in directions.split(",") if v.strip()]
    except ValueError:
        raise RecordingError(f"{path}: unreadable Indexes/Direction in the wave note") from None
    current = 0
    for i, (start, stop) in enumerate(zip(idx[:-1], idx[1:], strict=False)):
        d = dirs[i + 1] if i + 1 < len(dirs) else math.nan
        if d < 0:
            current = 1
        elif d > 0:
            current = 0
        segment[start:stop + 1] = current
    return segment


def _volts(values: np.ndarray) -> bool:
    """No lever deflects or oscillates by 100 um and no Asylum Z sensor travels that far: a
    column reaching 1e-4 is in volts (or damaged: `check_length` names NaN and inf)."""
    return bool(np.nanmax(np.abs(values)) > 1e-4) if values.size else False


def _number(value: Any) -> bool:
    return isinstance(value, float) and math.isfinite(value) and value > 0


def _text(b: Any) -> str:
    return b.decode("latin-1") if isinstance(b, bytes) else str(b)
