"""Thermal deflection time series with known f0, Q and k, generated as a lever moves.

`thermal_time_series` integrates a harmonic oscillator driven by white thermal force noise
EXACTLY in discrete time (the state transition ``A = expm(M dt)`` of ``x'' + (w0/Q) x' + w0^2 x
= F/m`` and the discrete noise covariance ``Sigma - A Sigma A^T`` with the stationary
``Sigma = diag(s2, w0^2 s2)``, ``s2 = C k_B T / k``), then adds white detector noise of
one-sided PSD ``background_m2_per_hz``. Spectra computed from it (`welch_spectrum`) are what
an instrument measures: windowed segments, averaged, with leakage and Gamma noise.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cholesky, expm
from scipy.signal import lfilter

from afmlearn.calibrate.sho import BOLTZMANN_J_PER_K

__all__ = ["thermal_time_series"]


def thermal_time_series(n_samples: int, *, sample_rate_hz: float, resonance_frequency_hz: float,
                        quality_factor: float, spring_constant_n_per_m: float,
                        temperature_k: float = 295.15, factor: float = 1.0,
                        background_m2_per_hz: float = 0.0,
                        rng: np.random.Generator) -> NDArray[np.float64]:
    """Deflection [m], shape (n_samples,), of a thermally driven oscillator plus detector noise.

    Parameters
    ----------
    n_samples : int
        Samples returned (after a burn-in of 10 amplitude decay times, discarded).
    sample_rate_hz, resonance_frequency_hz : float
        fs and f0 [Hz], f0 < fs / 2.
    quality_factor, spring_constant_n_per_m, temperature_k : float
        Q, k [N/m], T [K].
    factor : float
        ``C`` of ``<x^2> = C k_B T / k`` (1 for an ideal oscillator).
    background_m2_per_hz : float
        One-sided PSD of white detector noise [m^2/Hz], >= 0.
    rng : numpy.random.Generator
    """
    if not 0 < resonance_frequency_hz < sample_rate_hz / 2:
        raise ValueError("resonance_frequency_hz must be in (0, sample_rate_hz / 2)")
    w0 = 2 * math.pi * resonance_frequency_hz
    dt = 1.0 / sample_rate_hz
    s2 = factor * BOLTZMANN_J_PER_K * temperature_k / spring_constant_n_per_m
    a = expm(np.array([[0.0, 1.0], [-w0**2, -w0 / quality_factor]]) * dt)
    sigma = np.diag([s2, w0**2 * s2])
    q = sigma - a @ sigma @ a.T
    chol = cholesky(0.5 * (q + q.T), lower=True)
    burn = int(10 * quality_factor / (math.pi * resonance_frequency_hz) * sample_rate_hz) + 16
    w = chol @ rng.standard_normal((2, n_samples + burn))
    den = [1.0, -np.trace(a), np.linalg.det(a)]
    # x_n from s_{n+1} = A s_n + w_n: X = ((z^-1 - A22 z^-2) W1 + A12 z^-2 W2) / den(z)
    x = lfilter([0.0, 1.0, -a[1, 1]], den, w[0]) + lfilter([0.0, 0.0, a[0, 1]], den, w[1])
    x = x[burn:]
    if background_m2_per_hz > 0:
        x = x + rng.normal(0.0, math.sqrt(background_m2_per_hz * sample_rate_hz / 2), x.size)
    return x
