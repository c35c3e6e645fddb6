"""FFT windows and what they do to a measured power spectrum (bin response, bin correlation).

A periodogram bin of a windowed segment is not the power spectral density at the bin's
frequency: its expectation is the true PSD convolved with the window's power response
``|W(nu)|^2`` (``nu`` = offset from the bin centre in bins; Percival & Walden 1993, sec. 6.3),
and neighbouring bins of a tapered window are correlated. Both follow from the window alone.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import lru_cache
from typing import final

import numpy as np
from numpy.typing import NDArray

__all__ = ["Hann", "Rectangular", "Window", "bin_correlation", "power_response"]

FloatArray = NDArray[np.float64]


class Window(ABC):
    """A data taper applied to each segment before its FFT (one abstract hook: `values`)."""

    #: short name used in reports and configs
    name: str = "window"

    @abstractmethod
    def values(self, n: int) -> FloatArray:
        """The taper, shape (n,), dimensionless; ``n`` >= 2 samples (periodic form for FFTs)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def __eq__(self, other: object) -> bool:
        return type(other) is type(self)

    def __hash__(self) -> int:
        return hash(type(self))


@final
class Rectangular(Window):
    """No taper (``w = 1``): the periodogram's bin response is the Fejer kernel ~ sinc^2."""

    name = "rectangular"

    def values(self, n: int) -> FloatArray:
        return np.ones(_length(n))


@final
class Hann(Window):
    """Periodic Hann taper ``sin^2(pi n / N)`` (scipy's ``hann(N, sym=False)``)."""

    name = "hann"

    def values(self, n: int) -> FloatArray:
        n = _length(n)
        return np.sin(np.pi * np.arange(n) / n) ** 2


WINDOWS: dict[str, type[Window]] = {"rectangular": Rectangular, "hann": Hann}


def power_response(window: Window, n_segment: int, offsets: FloatArray) -> FloatArray:
    """Power response ``|W(nu)|^2 / (N sum w^2)`` of ``window`` at bin offsets ``nu``.

    Parameters
    ----------
    window : Window
        The taper.
    n_segment : int
        Samples per FFT segment N (>= 2).
    offsets : ndarray, shape (m,)
        Offsets from a bin centre [bins].

    Returns
    -------
    ndarray, shape (m,)
        Dimensionless weights; summed over a dense grid of spacing ``d`` and multiplied by
        ``d`` they integrate to 1 over the whole band (Parseval), so a white spectrum is
        reproduced exactly.
    """
    return _power_response(window, _length(n_segment), np.asarray(offsets, dtype=float))


def _power_response(window: Window, n: int, offsets: FloatArray) -> FloatArray:
    w = window.values(n)
    t = np.arange(n)
    out = np.empty(offsets.shape)
    for start in range(0, offsets.size, 512):  # bounded memory: 512 x N complex at a time
        nu = offsets[start:start + 512]
        dtft = np.exp(-2j * np.pi * np.outer(nu, t) / n) @ w
        out[start:start + 512] = np.abs(dtft) ** 2
    return out / (n * float(w @ w))


@lru_cache(maxsize=32)
def bin_correlation(window: Window, n_segment: int, max_lag: int = 4) -> tuple[float, ...]:
    """Correlation of the periodogram's power in bins ``l`` apart, for a white Gaussian input.

    ``rho_l = |sum w_n^2 exp(2 pi i l n / N)|^2 / (sum w_n^2)^2`` for l = 0 .. max_lag
    (0 for every l > 0 with a rectangular window; 4/9 and 1/36 at l = 1, 2 for Hann).

    Returns
    -------
    tuple of float, length max_lag + 1
        ``rho_0 = 1``, ``rho_1``, ...
    """
    n = _length(n_segment)
    w2 = window.values(n) ** 2
    t = np.arange(n)
    rho = [abs(np.sum(w2 * np.exp(2j * np.pi * lag * t / n))) ** 2 / float(w2.sum()) ** 2
           for lag in range(max_lag + 1)]
    return tuple(float(r) for r in rho)


def _length(n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
        raise ValueError(f"segment length must be an integer >= 2, got {n!r}")
    return int(n)
