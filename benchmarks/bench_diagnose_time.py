"""CPU time of one 8-set-point diagnosis, before/after in one run, decisions compared.

The cases are hidden-effect set-point series (``afmlearn.diagnose.synthetic.hidden_series``:
8 set-points at one free amplitude, recorded drive phase, 200 samples/period, 1 % noise,
30 periods per set-point), one draw per cause and a null, drawn from development seeds
(``[2026, 99, 200, index, cause code]``, disjoint from the evaluation's 2027); the files are
simulated once into ``outputs/bench_cache/diagnose_time/`` under neutral names. Each diagnosis
(``Diagnoser().fit(Experiment.read(path))``: no labels, no file name) runs in its own child
process from a source tree: ``--base REV`` adds a ``git archive`` snapshot of ``REV`` (its own
numba cache, compiled by a warm-up diagnosis before any clock starts), the working tree is
always run; the trees alternate per draw, so both see the same load. Recorded per run: the
process CPU time of the fit (``time.process_time``), the wall time, the load, the causes named,
the reported gain and every first-step candidate's chi2 drop, so that a speed-up is shown not
to change what the diagnosis says. Records go to
``outputs/bench_cache/diagnose_time/time.jsonl`` (appended); the section lists all of them and
the per-draw ratio of each (base, working tree) pair of the same run.

Run: ``python benchmarks/bench_diagnose_time.py [--base REV] [--causes a,b,..] [--index 0]
[--report-only] [--no-doc]`` (one diagnosis ~15-60 s CPU; one thread each).
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402
from pathlib import Path  # noqa: E402

import _common as C  # noqa: E402  -- first: puts the repository root on sys.path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "outputs" / "bench_cache" / "diagnose_time"
STORE = CACHE / "time.jsonl"
CAUSES = ("none", "higher_mode", "viscoelastic", "long_range_damping", "contact_geometry",
          "adhesion_hysteresis", "electrostatic", "detector_nonlinearity")


def _import_tree(tree: str):
    """Import afmlearn from ``tree`` (a fresh child process)."""
    sys.path.insert(0, tree)
    import afmlearn
    assert afmlearn.__file__.startswith(tree), afmlearn.__file__
    return afmlearn


def case_file(cause: str, index: int) -> Path:
    """The draw's series file (simulated on first use; a neutral, content-derived name)."""
    import hashlib

    import numpy as np

    from afmlearn.diagnose.synthetic import hidden_series

    key = f"{cause}:{index}:200:0.01:30"
    path = CACHE / (hashlib.sha1(key.encode()).hexdigest()[:16] + ".h5")
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        rng = np.random.default_rng([2026, 99, 200, index, CAUSES.index(cause)])
        tmp = path.with_name(f".{uuid.uuid4().hex}.h5")
        hidden_series(rng, tmp, causes=cause, n_points=8, samples_per_period=200,
                      n_periods=30, noise_level=0.01)
        os.replace(tmp, path)
    return path


def child(tree: str, path: str, tag: str, warm: str) -> dict:
    """One diagnosis of ``path`` from the sources in ``tree`` (after a warm-up on ``warm``)."""
    _import_tree(tree)
    from afmlearn.diagnose import Diagnoser
    from afmlearn.io import Experiment

    t = time.process_time()          # compile (or load) every kernel before the clock starts
    Diagnoser().fit(Experiment.read(warm).subset([0, 1]))
    compile_s = time.process_time() - t
    exp = Experiment.read(path)
    load0 = os.getloadavg()[0]
    t0, w0 = time.process_time(), time.perf_counter()
    d = Diagnoser().fit(exp)
    return {"tag": tag, "tree": tree, "file": Path(path).name,
            "cpu_s": time.process_time() - t0, "wall_s": time.perf_counter() - w0,
            "load": [load0, os.getloadavg()[0]], "compile_s": compile_s,
            "causes": [c.cause for c in d.causes_] or ["none"], "gain": float(d.gain_),
            "drops": {c.cause: float(c.delta_chi2) for c in d.candidates_}}


def _same(a: dict, b: dict) -> str:
    """How two runs of one draw compare: causes, largest relative drop difference, gain."""
    if a["causes"] != b["causes"]:
        return "causes differ"
    keys = set(a["drops"]) | set(b["drops"])
    rel = max((abs(a["drops"].get(k, 0.0) - b["drops"].get(k, 0.0))
               / max(abs(a["drops"].get(k, 0.0)), 1.0) for k in keys), default=0.0)
    return (f"same causes; drops equal to {rel:.0e}, gain {a['gain']:.4f} / {b['gain']:.4f}"
            if rel > 0 else f"same causes, drops and gain {b['gain']:.4f}")


def table(records: list[dict]) -> tuple[str, list[float]]:
    rows, ratios = [], []
    by_run: dict[str, list[dict]] = {}
    for r in records:
        by_run.setdefault(r.get("run", "?"), []).append(r)
    for run, recs in by_run.items():
        for cause in CAUSES:
            pair = [r for r in recs if r["cause"] == cause]
            base = next((r for r in pair if r["role"] == "base"), None)
            work = next((r for r in pair if r["role"] == "work"), None)
            if work is None:
                continue
            ratio = base["cpu_s"] / work["cpu_s"] if base else float("nan")
            if base:
                ratios.append(ratio)
            rows.append([run, cause, " + ".join(work["causes"]),
                         f"{base['cpu_s']:.1f}" if base else "-", f"{work['cpu_s']:.1f}",
                         f"{ratio:.2f}" if base else "-",
                         f"{work['wall_s']:.0f}", f"{work['load'][0]:.1f}",
                         _same(base, work) if base else "-"])
    return C.md_table(["run", "hidden cause", "named (working tree)", "CPU s base",
                       "CPU s working tree", "base / working tree", "wall s", "load",
                       "decisions"], rows), ratios


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", nargs=4, metavar=("TREE", "PATH", "TAG", "WARM"),
                    help=argparse.SUPPRESS)
    ap.add_argument("--base", default=None, help="git revision to compare (snapshot)")
    ap.add_argument("--causes", default=",".join(CAUSES))
    ap.add_argument("--index", type=int, default=0, help="draw index of every cause")
    ap.add_argument("--report-only", action="store_true")
    C.add_doc_flag(ap)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(*args.child)))
        return ""
    causes = [c for c in args.causes.split(",") if c]
    bad = [c for c in causes if c not in CAUSES]
    if bad:
        raise SystemExit(f"error: --causes: unknown {bad}; allowed {list(CAUSES)}")
    info = C.machine_info()
    if not args.report_only:
        run = f"{time.strftime('%Y-%m-%d %H:%M')} ({C.git_head()}" + \
            (f" vs {args.base})" if args.base else ")")
        trees = [(str(C.git_snapshot(args.base, CACHE)), "base")] if args.base else []
        trees.append((str(ROOT), "work"))
        warm = str(case_file("none", 0))
        for cause in causes:
            path = str(case_file(cause, args.index))
            for tree, role in trees:
                out = subprocess.run([sys.executable, __file__, "--child", tree, path, role,
                                      warm], check=True, capture_output=True,
                                     text=True).stdout
                rec = json.loads(out.strip().splitlines()[-1])
                rec.update(run=run, role=role, cause=cause, index=args.index)
                CACHE.mkdir(parents=True, exist_ok=True)
                with open(STORE, "a") as f:
                    f.write(json.dumps(rec) + "\n")
                print(f"[time] {role} {cause}: {rec['cpu_s']:.1f} s CPU, "
                      f"{'+'.join(rec['causes'])}", flush=True)
    records = [json.loads(line) for line in STORE.read_text().splitlines()] \
        if STORE.exists() else []
    tab, ratios = table(records)
    summary = (f"Median ratio base / working tree over {len(ratios)} draws: "
               f"**{statistics.median(ratios):.2f}x** (range {min(ratios):.2f}-"
               f"{max(ratios):.2f})." if ratios else "No base runs recorded.")
    body = f"""
One 8-set-point diagnosis per hidden cause (development draws, seed 2026; 200 spp / 1 %, 30
periods, recorded phase), each in its own process, one thread; "CPU s": process CPU time of
`Diagnoser().fit` (kernels compiled by a warm-up before the clock). The base tree (`--base`,
a `git archive` snapshot) and the working tree alternate per draw within one run. "decisions":
whether both name the same causes, and how far apart their first-step chi2 drops are
(largest relative difference) and the reported gains. Goal (issue 12): one 8-set-point
diagnosis <= 60 s. Records in run order (`{STORE.relative_to(ROOT)}`).

{tab}

{summary}
"""
    return C.write_section("diagnose_time", "Diagnosis CPU time, before/after in one run "
                           "(`bench_diagnose_time.py`)", body, info, write=not args.no_doc)


if __name__ == "__main__":
    main()
