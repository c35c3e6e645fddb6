"""`make demo`: simulate tapping-mode traces and a small sweep, print a summary, save figures.

Composes the real configs of conf/ (as `scripts/simulate.py` would) and calls
afmlearn.simulate.simulate for each run:

* steady tapping traces (TAP300AL-G, 10 nm gap, 15 nm free amplitude) for three force models:
  conservative DMT, viscoelastic DMT and hysteretic JKR;
* a small forward/reverse frequency sweep (41 points, 0.99--1.01 f0) with DMT.

Files go to outputs/demo/ (trace files) and outputs/demo/figures/ (PNG). The first run
compiles the simulator's kernels (a few minutes); later runs take seconds.

    python scripts/demo.py [--out outputs/demo]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from hydra import compose, initialize_config_dir

from afmlearn.plots import plot_sweep, plot_trace
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]

RUNS = [
    ("tapping_dmt", ["force=dmt"]),
    ("tapping_dmt_visco", ["force=dmt_visco"]),
    ("tapping_jkr_hysteretic", ["force=jkr_hysteretic"]),
    ("sweep_dmt", ["force=dmt", "scenario=sweep"]),
]

def _fixed(value: float, digits: int = 2) -> str:
    """``value`` with ``digits`` decimals, without a negative zero ("-0.00")."""
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


COLUMNS = [  # header, width, format(metrics, run name)
    ("run", 24, lambda m, name: name),
    ("model", 15, lambda m, name: m["model"]),
    ("scenario", 9, lambda m, name: m["scenario"]),
    ("A [nm]", 7, lambda m, name: f"{m['amplitude_m'] * 1e9:.2f}"),
    ("set-point", 9, lambda m, name: f"{m['set_point']:.2f}"),
    ("contact", 7, lambda m, name: f"{100 * m['contact_fraction']:.1f}%"),
    ("F_peak [nN]", 11, lambda m, name: f"{m['peak_force_n'] * 1e9:.2f}"),
    ("E_diss [eV/cyc]", 15, lambda m, name: _fixed(m["dissipated_energy_ev"])),
    ("coupling", 8, lambda m, name: f"{m['coupling_strength']:.3f}"),
    ("time [s]", 8, lambda m, name: f"{m['runtime_s']:.2f}"),
]


def _table(rows: list[tuple[str, dict]]) -> str:
    head = "  ".join(f"{h:>{w}}" if i > 2 else f"{h:<{w}}"
                     for i, (h, w, _) in enumerate(COLUMNS))
    lines = [head, "-" * len(head)]
    for name, m in rows:
        lines.append("  ".join(f"{f(m, name):>{w}}" if i > 2 else f"{f(m, name):<{w}}"
                               for i, (_, w, f) in enumerate(COLUMNS)))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "outputs" / "demo",
                        help="output folder (default: outputs/demo)")
    args = parser.parse_args()
    out = args.out.resolve()
    figures = out / "figures"
    t0 = time.perf_counter()
    results: list[tuple[str, dict]] = []
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3", job_name="demo"):
        for name, overrides in RUNS:
            cfg = compose("simulate", overrides=[*overrides, f"output={out / name}.h5",
                                                 "progress=false"])
            print(f"simulating {name} ...", flush=True)
            metrics, _ = simulate(cfg)
            results.append((name, metrics))
    print()
    print("Summary (amplitude: first harmonic; sweep: max amplitude, mean contact fraction and"
          " dissipation over rows)")
    print(_table(results))
    print()
    paths = []
    for name, metrics in results:
        if metrics["scenario"] == "sweep":
            paths += plot_sweep(metrics["output"], figures, prefix=name)
        elif name in ("tapping_dmt", "tapping_dmt_visco"):
            paths += plot_trace(metrics["output"], figures, prefix=name)
    print("Trace files (format v1, read with afmlearn.io.read_trace):")
    for _, metrics in results:
        print(f"  {metrics['output']}")
    print(f"Figures ({len(paths)}):")
    for p in paths:
        print(f"  {p}")
    print(f"Done in {time.perf_counter() - t0:.1f} s.")


if __name__ == "__main__":
    main()
