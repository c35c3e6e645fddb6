"""Thermal calibration: f0, Q and k from a thermal-noise spectrum fitted as it was measured.

Public API
----------
`PowerSpectrum`, `welch_spectrum`
    A measured spectrum with its window, segment length and number of averages; Welch's
    averaged periodogram of a deflection time series.
`ThermalFit`
    Oscillator + background fit (bin response of the window, Gamma likelihood of the
    averaged spectrum, Fisher intervals), k by the thermal method.
`ThermalCorrection`
    Mode / detector factor of the thermal method (Butt & Jaschke 0.817, 0.971, 1).
`BinResponse`: `PointSample`, `WindowResponse`, `BinAverage`; `Window`: `Rectangular`, `Hann`;
`NoiseModel`: `GammaLikelihood`, `AmplitudeLeastSquares`
    Strategies of the fit.
"""

from afmlearn.calibrate.correction import ThermalCorrection
from afmlearn.calibrate.noise import (
    AmplitudeLeastSquares,
    GammaLikelihood,
    NoiseModel,
    PowerLeastSquares,
)
from afmlearn.calibrate.response import BinAverage, BinResponse, PointSample, WindowResponse
from afmlearn.calibrate.spectrum import PowerSpectrum, welch_spectrum
from afmlearn.calibrate.thermal import PARAMETERS, ThermalFit
from afmlearn.calibrate.windows import Hann, Rectangular, Window

__all__ = [
    "PARAMETERS",
    "AmplitudeLeastSquares",
    "BinAverage",
    "BinResponse",
    "GammaLikelihood",
    "Hann",
    "NoiseModel",
    "PointSample",
    "PowerLeastSquares",
    "PowerSpectrum",
    "Rectangular",
    "ThermalCorrection",
    "ThermalFit",
    "Window",
    "WindowResponse",
    "welch_spectrum",
]
