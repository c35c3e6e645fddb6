"""Analyse an FM-AFM frequency-shift map Δf(z, V) (thin Hydra entry point).

Examples
--------
    python scripts/analyze_fm.py data=../shared/data/real/ncafm_fm_spectroscopy \\
        out_dir=outputs/fm spring_constant_n_per_m=1800 amplitude_m=0.5e-9 \\
        resonance_frequency_hz=19796.5 reference_vcpd_v=1.75

Reads a Δf map (folder with df_dataframe*.csv + z_piezo.csv, or one CSV table; calibration
from fm_calibration.json beside it or the three overrides) and writes <out_dir>/report.json
and figures (afmlearn.fm.analyze.analyze_fm; figures from afmlearn.plots.fm). Prints the named
cause, the held-out errors of the baseline and extended laws and V_cpd with its interval. Bad
input (missing calibration, truncated / non-numeric / mismatched tables) prints `error: ...`
and exits with status 2.
"""

from __future__ import annotations

import sys

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig

from afmlearn.fm.analyze import analyze_fm
from afmlearn.plots.fm import fm_figures


@hydra.main(config_path="../conf", config_name="analyze_fm", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.fm.analyze.analyze_fm` and print the summary."""
    with bad_input_exits(ValueError, OSError):
        calib = {k: cfg[k] for k in ("spring_constant_n_per_m", "amplitude_m",
                                     "resonance_frequency_hz") if cfg[k] is not None}
        rep = analyze_fm(cfg.data_path, cfg.out_dir, exclude_closest_m=cfg.exclude_closest_m,
                         heldout_every=cfg.heldout_every, reference_vcpd_v=cfg.reference_vcpd_v,
                         profile_points=cfg.profile_points,
                         window_variants_m=tuple(cfg.window_variants_m),
                         jackknife_blocks=cfg.jackknife_blocks,
                         figures=fm_figures if cfg.figures else None, **calib)
    vc = rep["vcpd"]
    lo, hi = vc["interval_95_v"]
    print(f"cause                {rep['cause']} (held-out gain {rep['gain']:.3f})")
    for key in ("baseline", "baseline_vcpd0", "extended"):
        print(f"{key:<20} held-out RMS {rep[key]['heldout_rms_hz']:.3f} Hz, "
              f"NRMSE {rep[key]['heldout_nrmse']:.4f}")
    print(f"V_cpd (apex)         {vc['value_v']:.3f} V, 95 % profile interval "
          f"[{_v(lo)}, {_v(hi)}] V; over fit windows "
          f"[{', '.join(_v(x) for x in vc['by_window_range_v'])}] V; "
          f"far field {vc['far_v']:.3f} V")
    if vc["jackknife"] is not None:
        jlo, jhi = vc["jackknife"]["interval_95_v"]
        print(f"V_cpd jackknife      {jlo:.3f} .. {jhi:.3f} V (95 %, row blocks left out)")
    print(rep["final"]["equation"])
    print(f"wrote {cfg.out_dir}/report.json")


def _v(x: float | None) -> str:
    return "unbounded" if x is None else f"{x:.3f}"


def _data_alias(argv: list[str]) -> list[str]:
    """``data=PATH`` -> ``data_path=PATH``: conf/data is a config group (QRNN data sets), so
    Hydra would read ``data=`` as the choice of one of its files."""
    return [("data_path=" + a[5:]) if a.startswith("data=") else a for a in argv]


if __name__ == "__main__":
    sys.argv = _data_alias(sys.argv)
    main()
