"""Diagnose the harmonics of a free (contact-less) oscillation record (thin Hydra entry point).

Examples
--------
    python scripts/diagnose_free.py \
        record=../shared/data/real/freqdemod_skpfm_cantilever/JAM_9p90__copy.h5
    python scripts/diagnose_free.py record=run.csv column=deflection unit=nm \
        calibration.sample_rate_hz=2e6 out_dir=outputs/free

Writes <out_dir>/report.json (design.md section 3 fields plus the evidence) and
free_diagnosis.png (afmlearn.plots.freeosc). Prints the cause, its held-out gain and the
candidates. Bad input (unreadable file, missing calibration, not a deflection record, a
record too short) prints `error: ...` and exits with status 2.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from afmlearn.freeosc.record import diagnose_recording
from afmlearn.plots.freeosc import plot_free_diagnosis


def _figures(diagnosis, y, prediction, out_dir, unit):
    return [plot_free_diagnosis(diagnosis, y, prediction, out_dir, unit=unit)]


@hydra.main(config_path="../conf", config_name="diagnose_free", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.freeosc.record.diagnose_recording` and print the finding."""
    calibration = OmegaConf.to_container(cfg.calibration, resolve=True) or {}
    # the config's values fill only what the file does not state; command-line ones override
    given = {o.split("=", 1)[0].lstrip("+~") for o in HydraConfig.get().overrides.task}
    overrides = {k: v for k, v in calibration.items() if f"calibration.{k}" in given}
    defaults = {k: v for k, v in calibration.items() if k not in overrides and v is not None}
    with bad_input_exits(ValueError, OSError):
        report = diagnose_recording(
            cfg.record, cfg.out_dir, heldout_fraction=cfg.heldout_fraction,
            lever_q=cfg.lever_q, block_periods=cfg.block_periods,
            figures=_figures if cfg.figures else None, column=cfg.column, unit=cfg.unit,
            defaults=defaults, **overrides)
    print(f"cause       {report['cause']}  (confidence {report['confidence']:.2f})")
    print(f"gain        {report['gain']:.4f}  held-out NRMSE "
          f"{report['baseline']['heldout_nrmse']:.4g} -> {report['extended']['heldout_nrmse']:.4g}")
    for cand in report["candidates"]:
        print(f"  {cand['model']:<22} {cand['cause']:<22} gain {cand['gain']:+.4f}")
    print(f"wrote {cfg.out_dir}/report.json")


if __name__ == "__main__":
    main()
