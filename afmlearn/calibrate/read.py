"""Thermal spectra from files: a Nanosurf ``.nid`` thermal tune, or a raw deflection time
series (CSV / NPZ / plain HDF5 by the column convention of docs/recordings.md) turned into
a Welch spectrum."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from afmlearn.calibrate.spectrum import PowerSpectrum, welch_spectrum
from afmlearn.calibrate.windows import Hann, Window
from afmlearn.io.instruments import RecordingError, reader_for

__all__ = ["read_spectrum"]


def read_spectrum(path: str | os.PathLike[str], *, n_averages: float | None = None,
                  window: Window | None = None, segment_length: int = 4096,
                  overlap: float = 0.5, sample_rate_hz: float | None = None,
                  column: str | None = None, unit: str | None = None) -> PowerSpectrum:
    """Read a thermal spectrum, or compute one from a deflection time series.

    Parameters
    ----------
    path : str or os.PathLike
        ``.nid`` (Nanosurf thermal tune: measured amplitude spectral density, its number of
        averages, the vendor's fit range, f0, Q, k and temperature), or a time series file.
    n_averages : float, optional
        Replaces the number of averages the file states (.nid).
    window : Window, optional
        For a .nid: the FFT window the instrument used, if known (the file does not say);
        for a time series: the taper of the Welch segments (default `Hann`).
    segment_length, overlap : int, float
        Welch segments of a time series (bin width = sample rate / segment_length).
    sample_rate_hz : float, optional
        Sampling rate of a time series without a ``time_*`` column or ``sample_rate_hz``.
    column, unit : str, optional
        Name and unit of a deflection dataset not named by the convention (e.g. ``s``, ``nm``).

    Returns
    -------
    PowerSpectrum
    """
    path = Path(path)
    reader = reader_for(path)
    options = {k: v for k, v in (("column", column), ("unit", unit)) if v is not None}
    parsed = reader.parse(path, **options)[0]
    if parsed.kind == "spectrum":
        header = dict(parsed.header)
        f = parsed.arrays["frequency_hz"]
        asd = parsed.arrays["asd_m_per_rthz"]
        averages = n_averages if n_averages is not None else header.get("n_averages")
        if averages is None:
            raise RecordingError(f"{path}: the number of averages is not in the file: pass "
                                 "n_averages=N")
        if "vendor_fit_asd_m_per_rthz" in parsed.arrays:
            header["vendor_fit_asd_m_per_rthz"] = parsed.arrays["vendor_fit_asd_m_per_rthz"]
        return PowerSpectrum(f, np.square(asd), n_averages=float(averages), window=window,
                             segment_length=None, source=f"{path} ({reader.name})",
                             header=header)
    if parsed.kind != "deflection":
        raise RecordingError(f"{path}: holds {parsed.kind.replace('_', ' ')} data, not a "
                             "thermal spectrum or a deflection time series")
    rate = sample_rate_hz or parsed.header.get("sample_rate_hz")
    if rate is None:
        raise RecordingError(f"{path}: missing calibration 'sample_rate_hz': pass "
                             "sample_rate_hz=VALUE (or a time_s column)")
    x = parsed.arrays["deflection_m"]
    if x.size < 2 * segment_length:
        raise RecordingError(f"{path}: {x.size} samples, fewer than two Welch segments of "
                             f"segment_length={segment_length}")
    taper = window or Hann()
    return welch_spectrum(x, float(rate), segment_length=int(segment_length), window=taper,
                          overlap=overlap,
                          source=f"{path}: Welch ({taper.name} window, N = {segment_length}, "
                                 f"overlap {overlap:g})")
