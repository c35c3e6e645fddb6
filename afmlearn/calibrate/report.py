"""`calibrate_file`: one thermal calibration from a file, its comparisons and calibration.json.

Steps: read the spectrum (`read.read_spectrum`); if the instrument's window is unknown, infer
it from the data (`infer_window`: neighbouring bins of a tapered window are correlated, of a
rectangular one not); fit `ThermalFit` with that window's bin response and the Gamma
likelihood; fit the naive variants too (least squares on the ASD or on the PSD, maximum
likelihood without bin response) so the report shows what each assumption does to Q, and
check the line shape with a second oscillator (`lineshape.second_peak_check`); write
``calibration.json`` with the trace format's names and intervals.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from afmlearn.calibrate.correction import ThermalCorrection
from afmlearn.calibrate.lineshape import second_peak_check
from afmlearn.calibrate.noise import AmplitudeLeastSquares, GammaLikelihood, PowerLeastSquares
from afmlearn.calibrate.read import read_spectrum
from afmlearn.calibrate.response import PointSample, WindowResponse
from afmlearn.calibrate.spectrum import PowerSpectrum
from afmlearn.calibrate.thermal import ThermalFit
from afmlearn.calibrate.windows import Hann, Rectangular, Window, bin_correlation
from afmlearn.io import write_json

__all__ = ["DEFAULT_TEMPERATURE_K", "calibrate_file", "calibrate_spectrum", "infer_window"]

log = logging.getLogger(__name__)

#: lever temperature assumed when neither the file nor the user states one (22 degC)
DEFAULT_TEMPERATURE_K = 295.15


def infer_window(fit: ThermalFit) -> tuple[Window, float]:
    """The window whose bin correlation matches the data: `Rectangular` (lag-1 power
    correlation 0) or `Hann` (4/9), by the measured lag-1 correlation of the normalised
    residuals ``P / E - 1`` of a first fit, over the bins where the oscillator is below 5 % of
    the background (there the residual is noise, not misfit). Returns ``(window, measured)``.
    """
    f = fit.frequency_hz_
    r = fit.observed_m2_per_hz_ / fit.expected_m2_per_hz_ - 1.0
    quiet = fit.model_psd(f) - fit.background_m2_per_hz_ < 0.05 * fit.background_m2_per_hz_
    a, b = r[:-1], r[1:]
    both = quiet[:-1] & quiet[1:]
    if both.sum() < 50:
        both = np.ones_like(both)
    measured = float(np.corrcoef(a[both], b[both])[0, 1])
    hann = bin_correlation(Hann(), 1024)[1]
    window: Window = Rectangular() if measured < hann / 2 else Hann()
    return window, measured


def calibrate_spectrum(spectrum: PowerSpectrum, *, temperature_k: float | None = None,
                       correction: ThermalCorrection | None = None,
                       fit_range_hz: tuple[float, float] | None = None,
                       window: Window | None = None, confidence: float = 0.95,
                       compare: bool = True) -> tuple[ThermalFit, dict[str, Any]]:
    """Fit ``spectrum`` as it was measured; returns the fit and the JSON-ready result.

    Parameters
    ----------
    spectrum : PowerSpectrum
    temperature_k : float, optional
        Lever temperature [K]; default the file's, else `DEFAULT_TEMPERATURE_K`.
    correction : ThermalCorrection, optional
        Default `ThermalCorrection.optical_lever` (Butt & Jaschke 0.817).
    fit_range_hz : (float, float), optional
        Default the file's fit range, else the peak +- 30 line widths.
    window : Window, optional
        The instrument's window when the spectrum does not say; default inferred.
    compare : bool
        Also fit the naive variants (``"comparison"``) and a second oscillator
        (``"line_shape_check"``, `lineshape.second_peak_check`).
    """
    notes = []
    temp = temperature_k or spectrum.header.get("temperature_k")
    if temp is None:
        temp = DEFAULT_TEMPERATURE_K
        notes.append(f"temperature not stated: {DEFAULT_TEMPERATURE_K} K assumed "
                     "(pass temperature_k=...)")
    measured_corr = None
    win = spectrum.window or window
    correction = correction or ThermalCorrection.optical_lever()
    common = dict(temperature_k=float(temp), correction=correction, fit_range_hz=fit_range_hz,
                  confidence=confidence)
    if win is None:
        first = ThermalFit(response=PointSample(), noise=GammaLikelihood(), **common)
        win, measured_corr = infer_window(first.fit(spectrum))
        notes.append(f"FFT window not stated by the file: {win.name} inferred from the "
                     f"lag-1 correlation of neighbouring bins ({measured_corr:.3f}; 0 for "
                     f"rectangular, {bin_correlation(Hann(), 1024)[1]:.3f} for Hann)")
    n_seg = spectrum.segment_length or 4096
    fit = ThermalFit(response=WindowResponse(win, n_seg), noise=GammaLikelihood(),
                     **common).fit(spectrum)
    result: dict[str, Any] = fit.calibration()
    result["source"] = spectrum.source
    result["window"] = {"name": win.name, "stated_by_file": spectrum.window is not None,
                        "measured_lag1_bin_correlation": measured_corr}
    r = fit.observed_m2_per_hz_ / fit.expected_m2_per_hz_ - 1.0
    result["background_relative_scatter"] = float(np.std(r))
    result["expected_relative_scatter"] = float(1.0 / np.sqrt(fit.n_averages_))
    if compare:
        variants = {
            "least_squares_asd_point": (PointSample(), AmplitudeLeastSquares()),
            "least_squares_psd_point": (PointSample(), PowerLeastSquares()),
            "max_likelihood_point": (PointSample(), GammaLikelihood()),
            "max_likelihood_window": (WindowResponse(win, n_seg), GammaLikelihood()),
        }
        result["comparison"] = {}
        for name, (response, noise) in variants.items():
            other = ThermalFit(response=response, noise=noise, **common).fit(spectrum)
            result["comparison"][name] = {
                "resonance_frequency_hz": other.resonance_frequency_hz_,
                "quality_factor": other.quality_factor_,
                "quality_factor_interval": list(other.intervals_["quality_factor"]),
                "spring_constant_n_per_m": other.spring_constant_n_per_m_,
                "reduced_deviance": other.reduced_deviance_}
        result["line_shape_check"] = second_peak_check(spectrum, fit)
    vendor = {k.removeprefix("vendor_"): v for k, v in spectrum.header.items()
              if k.startswith("vendor_") and isinstance(v, float)}
    if vendor:
        result["vendor"] = vendor
        result["relative_difference_to_vendor"] = {
            name: getattr(fit, f"{name}_") / value - 1.0 for name, value in vendor.items()
            if hasattr(fit, f"{name}_")}
    if fit.reduced_deviance_ > 1.5:
        notes.append(f"reduced deviance {fit.reduced_deviance_:.2f} > 1.5: the oscillator + "
                     "white background does not describe the spectrum within its noise; "
                     "the intervals are widened by it, and Q depends on the fit's weighting "
                     "(see comparison)")
    result["notes"] = notes
    for note in notes:
        log.debug(note)
    return fit, result


def calibrate_file(path: str | os.PathLike[str], out_dir: str | os.PathLike[str] | None = None,
                   *, read_options: dict[str, Any] | None = None,
                   **options: Any) -> tuple[ThermalFit, dict[str, Any], PowerSpectrum]:
    """`read_spectrum` + `calibrate_spectrum`; writes ``out_dir/calibration.json`` if given.

    Returns
    -------
    (ThermalFit, dict, PowerSpectrum)
        The fit, the result (as written) and the spectrum.
    """
    spectrum = read_spectrum(path, **(read_options or {}))
    fit, result = calibrate_spectrum(spectrum, **options)
    result["input"] = str(Path(path).resolve())
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        result["files"] = {"calibration": str(out / "calibration.json")}
        write_json(out / "calibration.json", result)
    return fit, result, spectrum
