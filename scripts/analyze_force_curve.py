"""Analyse a static force curve (thin Hydra entry point): contact law, exponent, adhesion.

Examples
--------
    python scripts/analyze_force_curve.py curve=fmt-igor-fd_SiN_FD_plot.ibw
    python scripts/analyze_force_curve.py curve=spot.jpk-force out_dir=outputs/fc index=0
    python scripts/analyze_force_curve.py curve=outputs/s.h5      # converted by scripts/convert.py

Fits the DMT sphere (exponent 1.5) and the free-exponent contact law to the approach, predicts
the retraction's repulsive part with both (held-out gain), measures jump-in, pull-off and the
loop work (afmlearn.forcecurve, docs/real_data.md), writes <out_dir>/report.json. Bad input
(unreadable file, not a static curve, missing calibration) prints `error: ...` and exits 2.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig, OmegaConf

from afmlearn.forcecurve.report import analyse_file


@hydra.main(config_path="../conf", config_name="analyze_force_curve", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.forcecurve.report.analyse_file` and print the finding."""
    given = OmegaConf.to_container(cfg.calibration, resolve=True) or {}
    with bad_input_exits(ValueError, OSError):
        r = analyse_file(cfg.curve, cfg.out_dir, index=int(cfg.index),
                         baseline_fraction=float(cfg.baseline_fraction),
                         **{k: v for k, v in given.items() if v is not None})
    for name in ("baseline", "extended"):
        fit = r[name]
        sign = "-" if fit["adhesion_n"] >= 0 else "+"
        print(f"{name:<9} F [N] = {fit['prefactor']:.4g} (d_c - d [m])^{fit['exponent']:.3g} "
              f"{sign} {abs(fit['adhesion_n']) * 1e9:.4g} nN in contact;  approach RMS "
              f"{fit['rms_approach_n'] * 1e12:.3g} pN, retraction NRMSE {fit['heldout_nrmse']:.4g}")
    print(f"gain      {r['gain']:+.3f}  (free exponent vs sphere, on the retraction)")
    print(f"adhesion  jump-in {r['jump_in_n'] * 1e9:.4g} nN, pull-off {r['pull_off_n'] * 1e9:.4g} "
          f"nN, loop work {r['loop_work_j']:.3g} J")
    print(f"wrote {cfg.out_dir}/report.json")


if __name__ == "__main__":
    main()
