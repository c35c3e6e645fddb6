"""Mode-coupling flag, sweet spot and orbit forecast on a recorded trace (thin Hydra entry point).

Examples
--------
    python scripts/infer_qrnn.py trace=outputs/demo/sweep_dmt.h5 out_dir=outputs/infer
    python scripts/infer_qrnn.py trace=run.h5 out_dir=out checkpoint=path/to/last.ckpt

Writes <out_dir>/coupling.json and figures (see afmlearn.qrnn.infer.infer). Bad input (the
checks of identify and diagnose -- clipped / saturated signal, NaN samples, fewer than 20
samples per drive period, non-positive rest gap -- a missing or malformed file, a trace shorter
than one input period plus the forecast horizon) prints one line `error: ...` and exits with
status 2.
"""

from __future__ import annotations

import hydra
import torch
from _cli import bad_input_exits
from omegaconf import DictConfig

from afmlearn.plots.qrnn import inference_figures
from afmlearn.qrnn.infer import infer


@hydra.main(config_path="../conf", config_name="infer_qrnn", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.qrnn.infer.infer` and print a short summary."""
    if cfg.get("threads"):
        torch.set_num_threads(int(cfg.threads))
    with bad_input_exits(ValueError):  # includes afmlearn.io.TraceFormatError
        result = infer(cfg.trace, cfg.out_dir, checkpoint=cfg.checkpoint,
                       threshold=None if cfg.threshold is None else float(cfg.threshold),
                       figures=inference_figures if cfg.figures else None)
    if result["is_sweep"]:
        print(f"{result['n_traces']} sweep points, flagged coupled: "
              f"{result['flagged_fraction']:.0%}")
        for spot in result["sweet_spot"]:
            iv = spot["interval_hz"]
            print(f"sweet spot ({spot['direction']}): "
                  + ("none" if iv is None else f"{iv[0] / 1e3:.3f} - {iv[1] / 1e3:.3f} kHz"))
    else:
        what = "probability" if result["calibrated"] else "score"
        print(f"coupling {what} {result['score']:.3f} (threshold {result['threshold']:.3g}), "
              f"flag {result['flag']}")
    print(f"wrote {result['output']}")
    for path in result["figures"]:
        print(f"      {path}")


if __name__ == "__main__":
    main()
