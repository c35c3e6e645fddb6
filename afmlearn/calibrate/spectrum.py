"""`PowerSpectrum`: a measured one-sided PSD with what is known of how it was measured.

`welch_spectrum` computes one from a deflection time series (Welch's averaged, windowed
periodogram, Welch 1967) and states its window, segment length and equivalent number of
independent averages.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.calibrate.windows import Hann, Window

__all__ = ["PowerSpectrum", "welch_spectrum"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True, eq=False)
class PowerSpectrum:
    """A one-sided power spectral density of the deflection, on equally spaced bins.

    Parameters
    ----------
    frequency_hz : ndarray, shape (n,)
        Bin centres [Hz], equally spaced, increasing.
    psd_m2_per_hz : ndarray, shape (n,)
        One-sided PSD [m^2/Hz] (an amplitude spectral density squared); >= 0.
    n_averages : float
        Equivalent number of independent averaged periodograms (the Gamma shape of each bin's
        noise: ``2 n_averages`` degrees of freedom), >= 1.
    window : Window or None
        Taper of each segment, None when unknown.
    segment_length : int or None
        Samples per FFT segment, None when unknown.
    sample_rate_hz : float or None
        Sampling rate of the time series, None when unknown.
    source : str
        Where the spectrum comes from (file and how it was read).
    header : dict
        Vendor metadata found in the file (e.g. the vendor's own f0, Q, k, temperature).
    """

    frequency_hz: FloatArray
    psd_m2_per_hz: FloatArray
    _: KW_ONLY
    n_averages: float = 1.0
    window: Window | None = None
    segment_length: int | None = None
    sample_rate_hz: float | None = None
    source: str = ""
    header: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        f = np.asarray(self.frequency_hz, dtype=float)
        p = np.asarray(self.psd_m2_per_hz, dtype=float)
        if f.ndim != 1 or f.size < 8 or p.shape != f.shape:
            raise ValueError("frequency_hz and psd_m2_per_hz must be 1-D of the same length "
                             f">= 8, got shapes {f.shape} and {p.shape}")
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(p))):
            raise ValueError("frequency_hz and psd_m2_per_hz must be finite")
        if np.any(p < 0):
            raise ValueError("psd_m2_per_hz must be >= 0 (a power spectral density)")
        step = np.diff(f)
        if not (np.all(step > 0) and np.ptp(step) <= 1e-6 * step.mean()):
            raise ValueError("frequency_hz must be equally spaced and increasing")
        if not (math.isfinite(self.n_averages) and self.n_averages >= 1):
            raise ValueError(f"n_averages must be >= 1, got {self.n_averages!r}")
        for name, a in (("frequency_hz", f), ("psd_m2_per_hz", p)):
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @property
    def bin_width_hz(self) -> float:
        """Bin spacing [Hz]."""
        return float((self.frequency_hz[-1] - self.frequency_hz[0]) / (self.frequency_hz.size - 1))

    @property
    def asd_m_per_rthz(self) -> FloatArray:
        """Amplitude spectral density sqrt(PSD) [m/sqrt(Hz)], shape (n,)."""
        return np.sqrt(self.psd_m2_per_hz)


def welch_spectrum(deflection_m: FloatArray, sample_rate_hz: float, *, segment_length: int,
                   window: Window | None = None, overlap: float = 0.5,
                   source: str = "") -> PowerSpectrum:
    """Welch's averaged periodogram of a deflection time series.

    Parameters
    ----------
    deflection_m : array-like, shape (n,)
        Deflection [m] (any sign convention: the PSD does not see it).
    sample_rate_hz : float
        Sampling rate [Hz], > 0.
    segment_length : int
        Samples per segment N (sets the bin width ``sample_rate_hz / N``), 16 <= N <= n.
    window : Window, optional
        Taper of each segment; default `Hann`.
    overlap : float
        Fraction of a segment shared with the next, in [0, 1).

    Returns
    -------
    PowerSpectrum
        One-sided PSD [m^2/Hz] at ``k sample_rate_hz / N`` (k = 0 .. N/2), each segment's mean
        removed; ``n_averages`` is the equivalent number of independent periodograms
        (Percival & Walden 1993, eq. 292b: overlapping tapered segments are not independent).
    """
    window = Hann() if window is None else window
    x = np.asarray(deflection_m, dtype=float)
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        raise ValueError("deflection_m must be a finite 1-D array")
    if not (isinstance(sample_rate_hz, int | float) and sample_rate_hz > 0):
        raise ValueError(f"sample_rate_hz must be > 0, got {sample_rate_hz!r}")
    if isinstance(segment_length, bool) or not isinstance(segment_length, int | np.integer) \
            or not 16 <= segment_length <= x.size:
        raise ValueError(f"segment_length must be an integer in [16, {x.size}], "
                         f"got {segment_length!r}")
    if not 0 <= overlap < 1:
        raise ValueError(f"overlap must be in [0, 1), got {overlap!r}")
    n = int(segment_length)
    step = max(1, int(round(n * (1.0 - overlap))))
    starts = np.arange(0, x.size - n + 1, step)
    w = window.values(n)
    segments = x[starts[:, None] + np.arange(n)]
    segments = segments - segments.mean(axis=1, keepdims=True)
    spectra = np.abs(np.fft.rfft(segments * w, axis=1)) ** 2
    psd = spectra.mean(axis=0) / (sample_rate_hz * float(w @ w))
    psd[1:n // 2 + (n % 2)] *= 2.0  # one-sided: fold negative frequencies (not DC, Nyquist)
    freq = np.fft.rfftfreq(n, 1.0 / sample_rate_hz)
    return PowerSpectrum(freq, psd, n_averages=equivalent_averages(w, starts.size, step),
                         window=window, segment_length=n, sample_rate_hz=float(sample_rate_hz),
                         source=source or f"Welch, {window.name} window, N = {n}, "
                                          f"overlap {overlap:g}, {starts.size} segments")


def equivalent_averages(w: FloatArray, n_segments: int, step: int) -> float:
    """Equivalent number of independent periodograms of ``n_segments`` segments of taper ``w``
    shifted by ``step`` samples (half the equivalent degrees of freedom, P&W eq. 292b)."""
    n = w.size
    denom = 1.0
    w2 = float(w @ w)
    for j in range(1, n_segments):
        shift = j * step
        if shift >= n:
            break
        rho = float(w[:n - shift] @ w[shift:]) / w2
        denom += 2.0 * (1.0 - j / n_segments) * rho**2
    return n_segments / denom
