"""Nanosurf ``.nid`` thermal-tune files (read with nsfopen): the thermal spectrum.

The file holds the measured amplitude spectral density (group "Spectrum FFT", m/sqrt(Hz),
equally spaced bins from 0 Hz) and the vendor's fitted curve ("Spectrum Fit"), with a header
("DataSet-Info") stating the vendor's f0, Q, k, the number of averages, the bin width, the fit
range and the lever temperature. A .nid thermal tune is not a trace: scripts/calibrate.py
reads it (`afmlearn.calibrate.read_spectrum`).
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any, final

import numpy as np

from afmlearn.io.instruments.base import InstrumentReader, Parsed
from afmlearn.io.instruments.errors import RecordingError

__all__ = ["NanosurfReader", "parse_quantity"]

_PREFIX = {"f": 1e-15, "p": 1e-12, "n": 1e-9, "u": 1e-6, "µ": 1e-6, "m": 1e-3, "": 1.0,
           "k": 1e3, "M": 1e6, "G": 1e9}


@final
class NanosurfReader(InstrumentReader):
    """Nanosurf ``.nid`` thermal tune: arrays ``frequency_hz``, ``asd_m_per_rthz`` and
    ``vendor_fit_asd_m_per_rthz``; header ``vendor_*`` values, ``temperature_k``,
    ``n_averages``, ``fit_range_hz``."""

    suffixes = (".nid",)
    name = "a Nanosurf .nid file"

    def _parse(self, path: Path, options: Mapping[str, Any]) -> Parsed:
        from NSFopen.read import read

        with warnings.catch_warnings():  # nsfopen calls a pandas API deprecated in pandas 3
            warnings.simplefilter("ignore")
            nid = read(str(path))
        data, param = nid.data, nid.param
        spectra = {key: np.asarray(data[key], dtype=float).ravel() for key in data.index}
        measured = [v for k, v in spectra.items() if "FFT" in k and "Spectral" in k[-1]]
        fitted = [v for k, v in spectra.items() if "Fit" in k and "Spectral" in k[-1]]
        if not measured:
            raise RecordingError(f"{path}: no thermal spectrum ('Spectrum FFT' amplitude "
                                 f"spectral density) in this .nid; found {list(data.index)}")
        asd = measured[0]
        if (bad := int(np.sum(~np.isfinite(asd) | (asd < 0)))) or not asd.size:
            raise RecordingError(f"{path}: the spectrum holds {bad} negative or non-finite "
                                 f"values of {asd.size} (an amplitude spectral density is "
                                 "finite and >= 0): corrupted file?")
        section = _fft_section(param["HeaderDump"])
        if section is None:
            raise RecordingError(f"{path}: no 'Spectrum FFT' amplitude-spectral-density data "
                                 "set in the .nid header (DataSet groups)")
        unit = str(section.get("Dim2Unit", ""))
        if unit.replace(" ", "") != "m/sqrt(Hz)":
            raise RecordingError(f"{path}: spectrum in {unit!r}, expected m/sqrt(Hz) "
                                 "(a deflection calibrated in metres)")
        try:
            f_min, f_range = float(section["Dim0Min"]), float(section["Dim0Range"])
        except (KeyError, ValueError):
            raise RecordingError(f"{path}: the spectrum's frequency axis (Dim0Min, Dim0Range) "
                                 "is missing or not a number") from None
        freq = np.linspace(f_min, f_min + f_range, asd.size)
        info = dict(param["HeaderDump"].get("DataSet-Info", {}))
        header: dict[str, Any] = {"description": f"Nanosurf thermal tune {path.name}",
                                  "vendor_header": {str(k): str(v) for k, v in info.items()}}
        for key, name in (("Frequency:", "vendor_resonance_frequency_hz"),
                          ("Q Factor:", "vendor_quality_factor"),
                          ("Spring Constant:", "vendor_spring_constant_n_per_m"),
                          ("Averages", "n_averages"), ("Resolution", "bin_width_hz")):
            value = parse_quantity(info.get(key))
            if value is not None:
                header[name] = value
        lo, hi = parse_quantity(info.get("Peak fit min")), parse_quantity(info.get("Peak fit max"))
        if lo is not None and hi is not None and hi > lo:
            header["fit_range_hz"] = (lo, hi)
        temp = info.get("Cantilever temperature")
        if temp is not None and (t := parse_quantity(str(temp).split("°")[0].split("Â")[0]))\
                is not None:
            header["temperature_k"] = t + 273.15
        arrays = {"frequency_hz": freq, "asd_m_per_rthz": asd}
        if fitted:
            arrays["vendor_fit_asd_m_per_rthz"] = fitted[0]
        return Parsed("spectrum", arrays, header)


def _fft_section(header: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The header section of the measured thermal spectrum: the data set whose ``Frame`` is
    ``Spectrum FFT`` and whose ``Dim2Name`` is a spectral density. A .nid may hold other
    groups before it (a frequency sweep, images): their axes are not the spectrum's."""
    groups = header.get("DataSet", {})
    for g in range(int(groups.get("GroupCount", 0) or 0)):
        for c in range(int(groups.get(f"Gr{g}-Count", 0) or 0)):
            section = header.get(groups.get(f"Gr{g}-Ch{c}", ""), {})
            if (section.get("Frame") == "Spectrum FFT"
                    and "Spectral" in str(section.get("Dim2Name", ""))):
                return section
    return None


def parse_quantity(text: Any) -> float | None:
    """``"179.8kHz"`` -> 179800.0, ``"27.13 N/m"`` -> 27.13, ``"1000"`` -> 1000.0; else None."""
    if text is None:
        return None
    match = re.match(r"\s*([-+]?\d*\.?\d+(?:[eE][-+]?\d+)?)\s*([fpnuµmkMG]?)", str(text))
    if not match:
        return None
    value = float(match.group(1))
    rest = str(text)[match.end(2):].strip()
    prefix = match.group(2)
    # a prefix only counts when a unit follows it ("27.13 N/m": no prefix; "1 m" is metres)
    if prefix and not rest[:1].isalpha() and not rest.startswith("/"):
        if prefix == "m" and not rest:
            prefix = ""
    value *= _PREFIX.get(prefix, 1.0)
    return value if math.isfinite(value) else None
