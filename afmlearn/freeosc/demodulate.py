"""Complex demodulation of a free oscillation: instantaneous amplitude, phase and frequency.

A self-oscillating (FM) lever has no external clock: its own fundamental is the clock. The
record is multiplied by ``exp(-i 2 pi f_c t)`` (``f_c`` = the spectral peak), low-passed
(zero-phase Butterworth, cut-off well below ``f_c`` so that the dc term and the harmonics,
which land at ``-f_c`` and ``(n - 1) f_c`` after the shift, are rejected), and the result
gives ``x_1(t) = A(t) cos(phi(t))`` of the fundamental alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

__all__ = ["Demodulation", "demodulate", "peak_frequency"]

FloatArray = NDArray[np.float64]

#: low-pass order of the demodulator
_ORDER = 4
#: samples dropped at each end of the record (filter edge transients), in cut-off periods
_EDGE_PERIODS = 3.0


@final
@dataclass(frozen=True, eq=False)
class Demodulation:
    """Instantaneous state of the fundamental, ``x_1(t) = amplitude cos(phase)``.

    Attributes
    ----------
    time_s : ndarray, shape (n,)
        Sample times [s] from the record's first sample.
    amplitude : ndarray, shape (n,)
        Amplitude ``A(t)`` of the fundamental, units of the record.
    phase : ndarray, shape (n,)
        Unwrapped phase ``phi(t)`` [rad], increasing.
    carrier_hz : float
        Demodulation frequency ``f_c`` [Hz].
    cutoff_hz : float
        Low-pass cut-off [Hz] (bandwidth of the tracked amplitude and frequency).
    valid : ndarray of bool, shape (n,)
        False within the filter's edge transients at both ends.
    """

    time_s: FloatArray
    amplitude: FloatArray
    phase: FloatArray
    carrier_hz: float
    cutoff_hz: float
    valid: NDArray[np.bool_]

    @property
    def frequency_hz(self) -> FloatArray:
        """Instantaneous frequency ``phi'(t) / 2 pi`` [Hz], shape (n,)."""
        return np.gradient(self.phase, self.time_s) / (2.0 * math.pi)

    def fundamental(self) -> FloatArray:
        """``A(t) cos(phi(t))``, shape (n,), units of the record."""
        return self.amplitude * np.cos(self.phase)

    def take(self, index: slice | NDArray[np.intp]) -> Demodulation:
        """The same state on a subset of samples (a span or a selection)."""
        return Demodulation(time_s=self.time_s[index], amplitude=self.amplitude[index],
                            phase=self.phase[index], carrier_hz=self.carrier_hz,
                            cutoff_hz=self.cutoff_hz, valid=self.valid[index])


def peak_frequency(y: ArrayLike, *, sample_rate_hz: float) -> float:
    """Frequency [Hz] of the largest spectral peak (Hann window, parabolic interpolation)."""
    y = np.asarray(y, dtype=float)
    spec = np.abs(np.fft.rfft((y - y.mean()) * np.hanning(y.size)))
    spec[0] = 0.0
    i = int(np.argmax(spec[1:-1])) + 1
    a, b, c = np.log(spec[i - 1 : i + 2] + 1e-300)
    shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
    return float((i + shift) * sample_rate_hz / y.size)


def demodulate(y: ArrayLike, *, sample_rate_hz: float, carrier_hz: float | None = None,
               cutoff_hz: float | None = None) -> Demodulation:
    """Track the amplitude and phase of the fundamental of a free oscillation.

    Parameters
    ----------
    y : array-like, shape (n,)
        The record (any units), uniformly sampled.
    sample_rate_hz : float
        Sampling rate [Hz], > 0.
    carrier_hz : float, optional
        Demodulation frequency [Hz] in (0, Nyquist); default: the spectral peak.
    cutoff_hz : float, optional
        Low-pass cut-off [Hz] in (0, carrier_hz / 2); default ``carrier_hz / 20``.

    Returns
    -------
    Demodulation

    Raises
    ------
    ValueError
        On a record shorter than 64 samples, non-finite samples, or settings out of range.
    """
    y = np.asarray(y, dtype=float)
    if y.ndim != 1 or y.size < 64:
        raise ValueError(f"y must be 1-D with at least 64 samples, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise ValueError("y must be finite (no NaN/inf)")
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise ValueError(f"sample_rate_hz must be > 0, got {sample_rate_hz!r}")
    fc = peak_frequency(y, sample_rate_hz=sample_rate_hz) if carrier_hz is None else carrier_hz
    if not 0.0 < fc < sample_rate_hz / 2:
        raise ValueError(f"carrier_hz must lie in (0, {sample_rate_hz / 2:g}) Hz, got {fc!r}")
    cut = fc / 20.0 if cutoff_hz is None else cutoff_hz
    if not 0.0 < cut < fc / 2:
        raise ValueError(f"cutoff_hz must lie in (0, carrier_hz / 2 = {fc / 2:g}) Hz, got {cut!r}")
    t = np.arange(y.size) / sample_rate_hz
    ref = 2.0 * math.pi * fc * t
    sos = signal.butter(_ORDER, cut / (sample_rate_hz / 2), output="sos")
    z = signal.sosfiltfilt(sos, y * np.cos(ref)) - 1j * signal.sosfiltfilt(sos, y * np.sin(ref))
    z *= 2.0
    amp = np.abs(z)
    phase = np.unwrap(np.angle(z)) + ref
    edge = min(int(_EDGE_PERIODS * sample_rate_hz / cut), y.size // 4)
    valid = np.zeros(y.size, dtype=bool)
    valid[edge : y.size - edge] = True
    return Demodulation(time_s=t, amplitude=amp, phase=phase, carrier_hz=float(fc),
                        cutoff_hz=float(cut), valid=valid)
