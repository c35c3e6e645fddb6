"""`make demo`: diagnose a "measured" trace with a hidden effect, then tour the toolbox.

The main job (issue 5): a tapping-mode recording is simulated with one effect of the cause
vocabulary (or none) drawn at random and kept hidden; the diagnosis (afmlearn.diagnose) reads
the file without its labels, names the cause, extends the model and measures the gain on
held-out periods; only then is the truth printed. The report goes to outputs/demo/diagnose/.

Then the rest of the toolbox, composing the real configs of conf/ (as `scripts/simulate.py`
would) and calling afmlearn.simulate.simulate for each run:

* steady tapping traces (TAP300AL-G, 10 nm gap, 15 nm free amplitude) for three force models:
  conservative DMT, viscoelastic DMT and hysteretic JKR;
* a small forward/reverse frequency sweep (41 points, 0.99--1.01 f0) with DMT;
* force identification (afmlearn.identify) on a longer DMT recording (400 periods, 500 samples
  per period, 1 % noise): the identified equation, the force accuracy against the simulator's
  truth (which the identifier never sees) and the files of `scripts/identify.py`;
* the QRNN mode-coupling score of both sweeps with the shipped checkpoint (a plain DMT sweep
  and the 2-mode sweet-spot lever of docs/sweet_spot.md).

Files go to outputs/demo/ (trace files) and outputs/demo/figures/ (PNG). The first run
compiles the simulator's kernels (a few minutes); later runs take seconds.

    python scripts/demo.py [--out outputs/demo] [--seed N] [--diagnose-only]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir

from afmlearn.diagnose.report import diagnose_trace
from afmlearn.diagnose.synthetic import hidden_trace
from afmlearn.identify.infer import identify_trace
from afmlearn.io import read_trace
from afmlearn.metrics import force_accuracy
from afmlearn.plots import plot_sweep, plot_trace
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]

RUNS = [
    ("tapping_dmt", ["force=dmt"]),
    ("tapping_dmt_visco", ["force=dmt_visco"]),
    ("tapping_jkr_hysteretic", ["force=jkr_hysteretic"]),
    ("sweep_dmt", ["force=dmt", "scenario=sweep"]),
    # the dissertation's 2-mode lever at 6:1 internal resonance (docs/sweet_spot.md)
    ("sweep_sweet_spot", ["experiment=sweet_spot", "scenario.n_points=141",
                          "scenario.samples_per_point=4000", "scenario.samples_per_period=100"]),
]
#: the recording the demo identifies: long enough for the contact's harmonics to stand out
IDENTIFY = ("identify_dmt", ["force=dmt", "scenario.n_periods=400",
                             "scenario.samples_per_period=500", "scenario.settle_periods=3500"])

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
    parser.add_argument("--seed", type=int, default=None,
                        help="seed of the hidden draw (default: a fresh one, printed at the end)")
    parser.add_argument("--diagnose-only", action="store_true",
                        help="only the diagnosis (skip the simulator/identifier/QRNN tour)")
    args = parser.parse_args()
    out = args.out.resolve()
    figures = out / "figures"
    t0 = time.perf_counter()
    _diagnose(out, args.seed)
    if args.diagnose_only:
        print(f"Done in {time.perf_counter() - t0:.1f} s.")
        return
    results: list[tuple[str, dict]] = []
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3", job_name="demo"):
        for name, overrides in RUNS:
            cfg = compose("simulate", overrides=[*overrides, f"output={out / name}.h5",
                                                 "progress=false"])
            print(f"simulating {name} ...", flush=True)
            metrics, _ = simulate(cfg)
            results.append((name, metrics))
        name, overrides = IDENTIFY
        cfg = compose("simulate", overrides=[*overrides, f"output={out / name}.h5",
                                             "progress=false"])
        print(f"simulating {name} ...", flush=True)
        id_metrics, _ = simulate(cfg)
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
    _identify(id_metrics["output"], out / "identify")
    for _, m in results:
        if m["scenario"] == "sweep":
            _coupling(m["output"])
    print(f"Done in {time.perf_counter() - t0:.1f} s.")


def _diagnose(out: Path, seed: int | None) -> None:
    """Simulate a recording with a hidden effect, diagnose it, then reveal the truth."""
    seed = int(np.random.SeedSequence().entropy % 2**32) if seed is None else int(seed)
    path = out / "measured.h5"
    print("Simulating a 'measured' tapping trace with a hidden effect (300 periods, 500 "
          "samples/period, 1 % noise) ...", flush=True)
    case = hidden_trace(np.random.default_rng(seed), path, samples_per_period=500,
                        n_periods=300, noise_level=0.01)
    print(f"Diagnosing {path} (the diagnosis reads no labels) ...", flush=True)
    t = time.perf_counter()
    rep = diagnose_trace(path, out / "diagnose")
    print(f"  diagnosed in {time.perf_counter() - t:.1f} s")
    print(f"  cause:      {rep['cause']}  (confidence {rep['confidence']:.2f})")
    if rep["cause"] != "none":
        print(f"  gain:       {rep['gain']:.3f}  (held-out NRMSE "
              f"{rep['baseline']['heldout_nrmse']:.3g} -> {rep['extended']['heldout_nrmse']:.3g})")
    print(f"  extended:   {rep['extended']['equation']}")
    print(f"  report:     {out / 'diagnose' / 'report.md'}")
    verdict = "right" if rep["cause"] == case.cause else "WRONG"
    print(f"  truth (revealed now): {case.cause} {case.effect or ''} -> the diagnosis is "
          f"{verdict}; seed {seed} (python scripts/demo.py --seed {seed} repeats it)")
    print()


def _identify(path: str, out_dir: Path) -> None:
    """Identify the force of one simulated recording and compare with the truth."""
    print()
    print(f"Identifying the tip-sample force of {path} (labels are not read) ...", flush=True)
    t = time.perf_counter()
    res = identify_trace(path, out_dir)
    ide = res["identifier"]
    m = ide.model_
    print(f"  identified in {time.perf_counter() - t:.1f} s")
    print(f"  equation (dimensionless): {m.equation()}")
    print(f"  force (SI): {m.equation_si()}")
    s = ide.summary_
    exp = s["interaction_exponent"]
    ci = s.get("interaction_exponent_interval")
    exp_txt = "n/a" if exp is None else f"{exp:.2f}" + (
        f" (95 % profile interval {ci[0]:.2f}-{ci[1]:.2f})" if ci else "")
    print(f"  peak repulsive force {s['peak_repulsive_force_n'] * 1e9:.2f} nN, contact time "
          f"{s['contact_time_s'] * 1e9:.0f} ns, interaction exponent "
          f"{exp_txt}, held-out state accuracy "
          f"{s['state_accuracy_heldout']:.3f}")
    truth = read_trace(path, labels=True)  # the demo may compare with the truth
    k, ell = truth.spring_constant_n_per_m, float(np.mean(truth.gap_m))
    f_true = truth.labels.force_n / (k * ell)
    z_true = np.asarray(truth.gap_m) / ell - truth.labels.modal_m[0] / ell
    a0 = truth.labels.model["force"]["parameters"]["a0"]
    acc = force_accuracy(ide.force_, f_true, z_true, a0)
    print("  force accuracy vs the simulator's truth (1 - NRMSE): "
          + ", ".join(f"{k} {v['accuracy']:.3f}" for k, v in acc.items()))
    print(f"  results: {out_dir} (result.json, model.json, force.h5, figures)")


def _coupling(path: str) -> None:
    """QRNN coupling score of the simulated sweep with the shipped checkpoint."""
    from afmlearn.qrnn.infer import coupling_summary

    print()
    print(f"{Path(path).name}: {coupling_summary(path)}")


if __name__ == "__main__":
    main()
