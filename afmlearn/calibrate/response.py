"""How a spectrum analyser turns the true PSD into the value of one bin (the bin response).

Strategies (one abstract hook, `_kernel`): `PointSample` (the naive model: bin value = PSD at
the bin centre), `WindowResponse` (the expectation of a windowed periodogram: the PSD
convolved with the window's power response, `windows.power_response`), `BinAverage` (the PSD
averaged over the bin width, e.g. a finer spectrum decimated by bin averaging).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy.signal import fftconvolve

from afmlearn.calibrate.windows import Window, power_response

__all__ = ["BinAverage", "BinResponse", "PointSample", "WindowResponse"]

FloatArray = NDArray[np.float64]


class BinResponse(ABC):
    """Expected bin values of a spectrum measured from a true PSD (hook: `_kernel`)."""

    @abstractmethod
    def _kernel(self) -> tuple[int, FloatArray]:
        """``(oversampling s, weights)``: weights on bin offsets ``j / s``, j = -J .. J, that
        sum to 1."""

    def expected(self, psd: Callable[[FloatArray], FloatArray], frequency_hz: FloatArray,
                 bin_width_hz: float) -> FloatArray:
        """Expected value of each bin.

        Parameters
        ----------
        psd : callable
            True one-sided PSD [m^2/Hz] of frequency [Hz] (evaluated at ``|f|``).
        frequency_hz : ndarray, shape (n,)
            Equally spaced bin centres [Hz].
        bin_width_hz : float
            Bin spacing [Hz].

        Returns
        -------
        ndarray, shape (n,)
            ``sum_j weight_j PSD(f_k + (j / s) bin_width)`` [m^2/Hz].
        """
        s, weights = self._kernel()
        half = (weights.size - 1) // 2
        fine = frequency_hz[0] + bin_width_hz * (np.arange(
            -half, (frequency_hz.size - 1) * s + half + 1) / s)
        values = psd(np.abs(fine))
        if weights.size == 1:
            return values[::s]
        smooth = fftconvolve(values, weights[::-1], mode="valid")
        return smooth[::s]


@final
class PointSample(BinResponse):
    """Bin value = true PSD at the bin centre (what a plain curve fit assumes)."""

    def _kernel(self) -> tuple[int, FloatArray]:
        return 1, np.ones(1)

    def __repr__(self) -> str:
        return "PointSample()"


@final
@dataclass(frozen=True)
class BinAverage(BinResponse):
    """Bin value = true PSD averaged over the bin width (``oversampling`` points per bin)."""

    oversampling: int = 16

    def _kernel(self) -> tuple[int, FloatArray]:
        s = self.oversampling
        w = np.ones(s + 1)
        w[[0, -1]] = 0.5  # trapezoid over [-1/2, 1/2] bin
        return s, w / w.sum()


@final
@dataclass(frozen=True)
class WindowResponse(BinResponse):
    """Bin value = expectation of a windowed periodogram: the true PSD convolved with the
    window's power response ``|W(nu)|^2`` (P&W 1993 eq. 186b), truncated at ``half_width``
    bins and renormalised (the tails beyond carry < 0.1 % for a rectangular window at 256
    bins; aliasing from above the Nyquist frequency is neglected).

    Parameters
    ----------
    window : Window
        The taper of each segment.
    segment_length : int
        Samples per segment N (the kernel's shape in bins hardly depends on N once N > 100).
    half_width : int
        Bins on either side of the centre included in the kernel.
    oversampling : int
        Kernel points per bin.
    """

    window: Window
    segment_length: int = 4096
    half_width: int = 256
    oversampling: int = 8

    def _kernel(self) -> tuple[int, FloatArray]:
        return _window_kernel(self.window, self.segment_length, self.half_width,
                              self.oversampling)


_CACHE: dict[tuple[Window, int, int, int], tuple[int, FloatArray]] = {}


def _window_kernel(window: Window, n: int, half_width: int, s: int) -> tuple[int, FloatArray]:
    key = (window, n, half_width, s)
    if key not in _CACHE:
        offsets = np.arange(-half_width * s, half_width * s + 1) / s
        w = power_response(window, n, offsets)
        w.flags.writeable = False
        _CACHE[key] = (s, w / w.sum())
    return _CACHE[key]
