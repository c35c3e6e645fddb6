"""The thermal spectrum of a simple harmonic oscillator and the equipartition theorem.

One-sided PSD of the deflection of an oscillator of resonance ``f0``, quality factor ``Q``
driven by thermal (white) force noise:

    S(f) = P_dc f0^4 / ((f^2 - f0^2)^2 + (f f0 / Q)^2)          [m^2/Hz]

whose integral over 0 < f < inf is ``<x^2> = P_dc pi f0 Q / 2`` (exact). The thermal method
sets ``<x^2> = C k_B T / k`` (equipartition, with the mode / detector factor ``C`` of
`afmlearn.calibrate.correction.ThermalCorrection`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["BOLTZMANN_J_PER_K", "dc_level", "mean_square", "sho_psd"]

FloatArray = NDArray[np.float64]

#: Boltzmann constant [J/K] (exact, SI 2019)
BOLTZMANN_J_PER_K = 1.380649e-23


def sho_psd(frequency_hz: FloatArray, f0_hz: float, quality_factor: float,
            dc_m2_per_hz: float) -> FloatArray:
    """The oscillator's one-sided PSD [m^2/Hz] at ``frequency_hz`` (shape kept)."""
    f = np.asarray(frequency_hz, dtype=float)
    return dc_m2_per_hz * f0_hz**4 / ((f * f - f0_hz**2) ** 2 + (f * f0_hz / quality_factor) ** 2)


def mean_square(f0_hz: float, quality_factor: float, dc_m2_per_hz: float) -> float:
    """``<x^2> = P_dc pi f0 Q / 2`` [m^2]: the exact integral of `sho_psd` over f > 0."""
    return dc_m2_per_hz * math.pi * f0_hz * quality_factor / 2.0


def dc_level(f0_hz: float, quality_factor: float, spring_constant_n_per_m: float,
             temperature_k: float, factor: float) -> float:
    """``P_dc`` [m^2/Hz] such that ``<x^2> = factor k_B T / k`` (inverse of `mean_square`)."""
    variance = factor * BOLTZMANN_J_PER_K * temperature_k / spring_constant_n_per_m
    return variance * 2.0 / (math.pi * f0_hz * quality_factor)
