"""Figure of a thermal calibration (matplotlib, Agg canvas, PNG written atomically).

`plot_thermal_fit`
    The measured PSD around the peak with the fitted expectation (the instrument's bin
    response included) and the fitted true oscillator + background, the vendor's curve when
    the file has one, and the normalised residual ``P / E - 1`` with its expected noise band
    ``+- 1/sqrt(n_averages)``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from afmlearn.calibrate import PowerSpectrum, ThermalFit
from afmlearn.plots.trace import _out_dir, _save

__all__ = ["plot_thermal_fit"]


def plot_thermal_fit(fit: ThermalFit, spectrum: PowerSpectrum,
                     out_dir: str | os.PathLike[str], *, result: dict[str, Any] | None = None,
                     name: str = "thermal_fit.png") -> Path:
    """Draw the fit of ``spectrum`` (a fitted `ThermalFit`); returns the PNG's path."""
    f = fit.frequency_hz_
    f0, q = fit.resonance_frequency_hz_, fit.quality_factor_
    near = np.abs(f - f0) < 12 * f0 / q
    fig = Figure(figsize=(8.0, 6.4))
    FigureCanvasAgg(fig)
    ax, res = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    khz = f[near] / 1e3
    ax.semilogy(khz, fit.observed_m2_per_hz_[near], ".", ms=3, color="0.45", label="measured")
    ax.semilogy(khz, fit.expected_m2_per_hz_[near], "-", color="C3", lw=1.6,
                label="fit: expected bin value (window response)")
    ax.semilogy(khz, fit.model_psd(f[near]), "--", color="C0", lw=1.0,
                label="fit: true oscillator + background")
    vendor = spectrum.header.get("vendor_fit_asd_m_per_rthz")
    if vendor is not None:
        sel = np.isin(spectrum.frequency_hz, f[near])
        ax.semilogy(spectrum.frequency_hz[sel] / 1e3, np.square(vendor[sel]), ":", color="C2",
                    lw=1.2, label="vendor's fitted curve")
    lo, hi = fit.intervals_["quality_factor"]
    klo, khi = fit.intervals_["spring_constant_n_per_m"]
    ax.set_title(f"f0 = {f0 / 1e3:.3f} kHz, Q = {q:.1f} [{lo:.1f}, {hi:.1f}], "
                 f"k = {fit.spring_constant_n_per_m_:.3g} [{klo:.3g}, {khi:.3g}] N/m "
                 f"(C = {fit.correction_.factor}, T = {fit.temperature_k_:.1f} K)", fontsize=9)
    ax.set_ylabel("PSD [m$^2$/Hz]")
    ax.legend(fontsize=8)
    r = fit.observed_m2_per_hz_[near] / fit.expected_m2_per_hz_[near] - 1.0
    band = 1.0 / np.sqrt(fit.n_averages_)
    res.plot(khz, r, ".", ms=3, color="0.3")
    res.axhspan(-2 * band, 2 * band, color="C0", alpha=0.15, label="+-2/sqrt(N_avg)")
    res.axhline(0.0, color="k", lw=0.6)
    res.set_ylabel("P/E - 1")
    res.set_xlabel("frequency [kHz]")
    res.legend(fontsize=8, loc="upper right")
    if result is not None and result.get("reduced_deviance") is not None:
        res.set_title(f"reduced deviance {result['reduced_deviance']:.2f} "
                      f"(1 when the model and the noise statistics hold)", fontsize=8)
    fig.tight_layout()
    return _save(fig, _out_dir(out_dir) / name)
