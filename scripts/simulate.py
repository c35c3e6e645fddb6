"""Simulate a labelled AFM trace, sweep or dataset shard (thin Hydra entry point).

Examples
--------
    python scripts/simulate.py force=jkr_hysteretic cantilever=nclr scenario=sweep \
        noise.level=0.01 seed=0 output=outputs/x.h5
    python scripts/simulate.py experiment=sweet_spot
    python scripts/simulate.py scenario=spectroscopy 'scenario.gaps=[1.4,1.2,1.0,0.8]'
    python scripts/simulate.py -m shard.index='range(0,4)' shard.count=4 output=outputs/ds \
        hydra/launcher=joblib

All options live in conf/ (see conf/simulate.yaml); the work is done by
afmlearn.simulate.simulate. Bad settings print `error: ...` (one line) and exit with status 2.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from omegaconf import DictConfig

from afmlearn.simulate import simulate


@hydra.main(config_path="../conf", config_name="simulate", version_base="1.3")
def main(cfg: DictConfig) -> float:
    """Run :func:`afmlearn.simulate.simulate`; return the amplitude [m] (for sweepers)."""
    with bad_input_exits(ValueError):  # bad settings (and TraceFormatError) name the key
        metrics, _ = simulate(cfg)
    width = max(len(k) for k in metrics)
    for key, value in metrics.items():
        shown = f"{value:.6g}" if isinstance(value, float) else value
        print(f"{key:<{width}}  {shown}")
    return float(metrics["amplitude_m"])


if __name__ == "__main__":
    main()
