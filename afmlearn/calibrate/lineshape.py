"""`second_peak_check`: is the thermal line one oscillator? Refit with a second one.

A line that is not a single Lorentzian (a neighbouring mode, a resonance that drifted during
the averaging, a holder resonance) makes the single-oscillator Q depend on the fit's
weighting. This check refits the same spectrum, with the same bin response, noise model,
temperature and correction, as the sum of two oscillators plus the white background, started
from the single fit and a second peak at the largest smoothed excess of the data over it. It
reports the main peak's f0, Q and k, the second peak's frequency, Q and share of the power,
and the reduced deviance before and after: a large drop says the single-oscillator Q is a
property of the fit, not of the lever. ``supported`` says whether the drop is larger than a
single line would give by chance (3 more parameters; chi-square at `SECOND_PEAK_ALPHA`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.stats import chi2

from afmlearn.calibrate.sho import BOLTZMANN_J_PER_K, dc_level, mean_square, sho_psd
from afmlearn.calibrate.spectrum import PowerSpectrum
from afmlearn.calibrate.thermal import ThermalFit, _optimise

__all__ = ["second_peak_check", "SECOND_PEAK_ALPHA"]

#: false-alarm probability of the second-oscillator test (a single line wrongly split)
SECOND_PEAK_ALPHA = 1e-3


def second_peak_check(spectrum: PowerSpectrum, fit: ThermalFit) -> dict[str, Any]:
    """Two-oscillator refit of ``spectrum`` starting from the fitted single oscillator ``fit``.

    Returns
    -------
    dict
        ``main`` (f0 [Hz], Q, k [N/m]), ``second`` (frequency [Hz], Q, share of the
        oscillators' power), ``reduced_deviance`` (two peaks), ``reduced_deviance_single``,
        ``deviance_drop`` (total deviance, single minus two peaks), ``critical_drop`` (the
        chi-square point of 3 parameters at `SECOND_PEAK_ALPHA`, times the two-peak reduced
        deviance when > 1) and ``supported`` (the drop exceeds it: the line is not one
        oscillator).
    """
    f, p, e1 = fit.frequency_hz_, fit.observed_m2_per_hz_, fit.expected_m2_per_hz_
    f0, q, k, b = (fit.resonance_frequency_hz_, fit.quality_factor_,
                   fit.spring_constant_n_per_m_, fit.background_m2_per_hz_)
    width = f0 / q
    near = np.abs(f - f0) < 10 * width
    excess = uniform_filter1d(p - e1, size=max(3, int(width / spectrum.bin_width_hz)))
    f1 = float(f[near][np.argmax(excess[near])])
    temperature, factor = fit.temperature_k_, fit.correction_.factor
    response, noise, n_avg = fit.response_, fit.noise_, fit.n_averages_
    q1 = q / 2
    height = max(float(np.max(excess[near])), 1e-3 * float(np.max(e1)))
    # a second peak of that height: P_peak = P_dc Q^2 = 2 C k_B T Q / (pi f k)
    k1 = 2 * factor * BOLTZMANN_J_PER_K * temperature * q1 / (math.pi * f1 * height)
    theta0 = np.array([f0, q, k, b, f1, q1, k1])
    df = spectrum.bin_width_hz

    def model(u: np.ndarray):
        a0, a1, a2, bg, c0, c1, c2 = theta0 * np.exp(u)
        d_main = dc_level(a0, a1, a2, temperature, factor)
        d_second = dc_level(c0, c1, c2, temperature, factor)
        return lambda x: sho_psd(x, a0, a1, d_main) + sho_psd(x, c0, c1, d_second) + bg

    def objective(u: np.ndarray) -> float:
        e = response.expected(model(u), f, df)
        return noise.objective(p, e, n_avg) if np.all(e > 0) else math.inf

    steps = np.array([1 / q, 0.2, 0.2, 0.2, 1 / q1, 0.2, 0.2])  # frequencies: ~a line width
    u = _optimise(objective, np.zeros(7), steps=steps)
    u = _optimise(objective, u, steps=steps)  # a restart: Nelder-Mead in 7-D stalls easily
    e2 = response.expected(model(u), f, df)
    theta = theta0 * np.exp(u)
    main, second = (0, 1, 2), (4, 5, 6)
    if theta[4] > theta[0] and theta[6] < theta[2]:  # label the stronger peak "main"
        main, second = second, main
    power = [mean_square(theta[i], theta[j], dc_level(theta[i], theta[j], theta[m],
                                                      temperature, factor))
             for i, j, m in (main, second)]
    dof = max(p.size - 7, 1)
    deviance = 2.0 * n_avg * float(np.sum(p / e2 - 1.0 - np.log(p / e2))) / dof
    # the second oscillator's 3 parameters must lower the total deviance by more than the
    # chi-square point at 0.1 % (scaled by the remaining overdispersion, if any)
    drop = fit.reduced_deviance_ * max(p.size - 4, 1) - deviance * dof
    critical = float(chi2.ppf(1.0 - SECOND_PEAK_ALPHA, 3)) * max(deviance, 1.0)
    return {
        "main": {"resonance_frequency_hz": float(theta[main[0]]),
                 "quality_factor": float(theta[main[1]]),
                 "spring_constant_n_per_m": float(theta[main[2]])},
        "second": {"frequency_hz": float(theta[second[0]]),
                   "quality_factor": float(theta[second[1]]),
                   "power_share": float(power[1] / (power[0] + power[1]))},
        "reduced_deviance": deviance,
        "reduced_deviance_single": fit.reduced_deviance_,
        "deviance_drop": float(drop),
        "critical_drop": critical,
        "supported": bool(drop > critical),
    }
