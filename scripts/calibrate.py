"""Thermal calibration of a cantilever from a thermal spectrum (thin Hydra entry point).

Examples
--------
    python scripts/calibrate.py spectrum=thermal.nid out_dir=outputs/calibrate
    python scripts/calibrate.py spectrum=thermal_series.h5 read.column=s read.unit=nm \
        read.sample_rate_hz=2e6 temperature_k=296

Fits a simple harmonic oscillator + white background to the spectrum as it was measured
(the FFT window's bin response, the Gamma statistics of an averaged spectrum), k by the
thermal method with the Butt & Jaschke optical-lever factor 0.817 (`correction=...`), and
writes <out_dir>/calibration.json (resonance_frequency_hz, quality_factor,
spring_constant_n_per_m, each with an interval; scripts/convert.py takes it) and
thermal_fit.png. Bad input prints `error: ...` (one line) and exits with status 2.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig, OmegaConf

from afmlearn.calibrate import ThermalCorrection
from afmlearn.calibrate.report import calibrate_file
from afmlearn.calibrate.windows import WINDOWS


@hydra.main(config_path="../conf", config_name="calibrate", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.calibrate.report.calibrate_file`, draw the fit, print the result."""
    with bad_input_exits(ValueError, OSError):  # RecordingError, bad settings: ValueErrors
        read = {k: v for k, v in OmegaConf.to_container(cfg.read).items() if v is not None}
        if "window" in read:
            if read["window"] not in WINDOWS:
                raise ValueError(f"read.window must be one of {sorted(WINDOWS)}, "
                                 f"got {read['window']!r}")
            read["window"] = WINDOWS[read["window"]]()
        fit_range = None if cfg.fit_range_hz is None else tuple(cfg.fit_range_hz)
        fit, result, spectrum = calibrate_file(
            cfg.spectrum, cfg.out_dir, read_options=read, temperature_k=cfg.temperature_k,
            correction=ThermalCorrection.named(cfg.correction), fit_range_hz=fit_range,
            confidence=float(cfg.confidence), compare=bool(cfg.compare))
    if cfg.figures:
        from afmlearn.plots.calibrate import plot_thermal_fit

        plot_thermal_fit(fit, spectrum, cfg.out_dir, result=result)
    for name in ("resonance_frequency_hz", "quality_factor", "spring_constant_n_per_m"):
        lo, hi = result[f"{name}_interval"]
        print(f"{name:<26} {result[name]:.6g}  [{lo:.6g}, {hi:.6g}]")
    check = result.get("line_shape_check")
    if check is not None and check["supported"]:
        print(f"line shape: with a second oscillator at {check['second']['frequency_hz']:.6g} Hz "
              f"({100 * check['second']['power_share']:.1f} % of the power) the main Q is "
              f"{check['main']['quality_factor']:.4g}; reduced deviance "
              f"{check['reduced_deviance_single']:.3g} -> {check['reduced_deviance']:.3g}")
    elif check is not None:
        print(f"line shape: one oscillator describes the line (a second one lowers the deviance "
              f"by {check['deviance_drop']:.3g}, below the {check['critical_drop']:.3g} a single "
              "line reaches by chance)")
    for name, value in result.get("vendor", {}).items():
        print(f"vendor {name:<19} {value:.6g}")
    for note in result["notes"]:
        print(f"note: {note}")
    print(f"wrote {result['files']['calibration']}")


if __name__ == "__main__":
    main()
