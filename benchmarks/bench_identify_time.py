"""CPU time of one two-amplitude joint identification, per stage, before/after in one run.

The case is ``bench_identify_accuracy.py --joint``'s "8 at two free amplitudes" series (rest
gaps 0.7, 0.9, 1.2, 1.4 L_ref at free amplitude 1.5 L_ref and 2.1, 2.7, 3.6, 4.2 at 4.5 L_ref;
200 samples/period, 1 % noise, 600 periods, recorded drive phase, seed 0; cached traces), fitted
by ``run_joint`` of that benchmark (``ForceIdentifier(n_bootstrap=0).fit_joint``). Each
identification runs in its own child process from a source tree: ``--base REV`` adds a
``git archive`` snapshot of ``REV`` (its own numba cache; compiled before the clock starts),
the working tree is always run; the trees alternate per exponent. Per stage: the CPU time
(``time.process_time``) inside each stage's ``run`` (nested calls count in their caller too).
Records go to ``outputs/bench_cache/identify/time.jsonl`` (appended); the section lists all of
them.

Run: ``python benchmarks/bench_identify_time.py [--base REV] [--exponents 1.5,2.0,2.27]
[--report-only] [--no-doc]`` (one identification ~50-90 s CPU; nice, one thread).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import _common as C  # first: puts the repository root on sys.path

ROOT = Path(__file__).resolve().parents[1]
STORE = ROOT / "outputs" / "bench_cache" / "identify" / "time.jsonl"
STAGES = [("ee_noise", "joint.NoiseScale"), ("ee_a0_profile", "joint.ContactOnsetProfile"),
          ("ee_selection", "joint.SupportSelection"), ("ee_offsets", "joint.OrbitOffsets"),
          ("ee_refine", "joint.Refinement"), ("oe_first", "output_error.OutputErrorFit"),
          ("oe_onsets", "output_error.OutputErrorStage._onsets"),
          ("oe_scan", "output_error.OutputErrorStage._scan"),
          ("oe_restart", "output_error.OutputErrorStage._restart"),
          ("oe_support", "output_error.OutputErrorSupport"),
          ("oe_profile", "output_error.OutputErrorProfile")]


def child(tree: str, p: float, tag: str) -> dict:
    """One identification from the sources in ``tree`` (run in a fresh process)."""
    sys.path.insert(0, tree)
    for mod in [m for m in sys.modules if m == "afmlearn" or m.startswith(("afmlearn.",
                                                                           "simulator"))]:
        del sys.modules[mod]
    import numpy as np

    import afmlearn
    assert afmlearn.__file__.startswith(tree), afmlearn.__file__
    from afmlearn.identify import joint as J
    from afmlearn.identify import output_error as OE
    from afmlearn.identify._simulate import simulate_period
    from afmlearn.identify.library import AFMLibrary, Indentation, InversePower

    kinds, p1, p2 = AFMLibrary([InversePower(2.0), Indentation(1.5)]).encode()
    t = time.process_time()  # compile (or load) the period map before the clock starts
    simulate_period(0.2, 1.0, 64, 1, 1.0, 1.0, 0.01, 0.012, 1.0, kinds, p1, p2,
                    np.array([-1e-5, 2.0]), 0.03)
    compile_s = time.process_time() - t
    timers: dict[str, float] = {}

    def wrap(owner: object, name: str, label: str) -> None:
        f = getattr(owner, name)

        def timed(*a: object, **kw: object) -> object:
            t0 = time.process_time()
            try:
                return f(*a, **kw)
            finally:
                timers[label] = timers.get(label, 0.0) + time.process_time() - t0
        setattr(owner, name, timed)

    mods = {"joint": J, "output_error": OE}
    for label, where in STAGES:
        mod, cls, *meth = where.split(".")
        wrap(getattr(mods[mod], cls), meth[0] if meth else "run", label)
    import _identify_cases as IC
    import bench_identify_accuracy as B

    case = B.joint_series(p, "200spp_1pct", periods=600, two_amplitudes=True)
    IC.series_for(case)
    load0 = os.getloadavg()[0]
    t0, w0 = time.process_time(), time.perf_counter()
    rec = B.run_joint(case, "8x2A", True)
    return {"tag": tag, "tree": tree, "p": p, "cpu_s": time.process_time() - t0,
            "wall_s": time.perf_counter() - w0, "load": [load0, os.getloadavg()[0]],
            "compile_s": compile_s, "stages": timers, "exponent": rec["exponent"],
            "interval": rec["interval"], "bounded": rec["bounded"],
            "acc": {k: v["accuracy"] for k, v in rec["acc"].items()},
            "a0_over_true": rec["a0_over_true"], "equation": rec["equation"],
            "profile": rec["profile"]}


def table(records: list[dict]) -> str:
    rows = []
    for r in records:
        st = r["stages"]
        ee = sum(v for k, v in st.items() if k.startswith("ee_"))
        oe = sum(v for k, v in st.items() if k.startswith("oe_") and k != "oe_first") + \
            st.get("oe_first", 0.0)
        iv = r["interval"]
        a = r["acc"]
        rows.append([r["p"], r.get("git", r["tag"]), f"{r['cpu_s']:.1f}",
                     f"{st.get('ee_a0_profile', 0):.1f}", f"{ee:.1f}",
                     f"{st.get('oe_profile', 0):.1f}", f"{oe:.1f}",
                     f"{r['wall_s']:.0f}", f"{r['load'][0]:.1f}",
                     f"{r['exponent']:.3f}", f"{iv[0]:.2f} – {iv[1]:.2f}",
                     f"{100 * a['whole']:.2f} / {100 * a['repulsive']:.2f} / "
                     f"{100 * a['near_a0']:.2f}", f"{r['a0_over_true']:.2f}"])
    return C.md_table(["true p", "code", "CPU s", "a0 profile", "EE stages", "OE profile",
                       "OE stage", "wall s", "load", "p", "95 % interval",
                       "force whole / repulsive / near a0 %", "a0 / true"], rows)


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", nargs=3, metavar=("TREE", "P", "TAG"), help=argparse.SUPPRESS)
    ap.add_argument("--base", default=None, help="git revision to compare (snapshot)")
    ap.add_argument("--exponents", default="1.5,2.0,2.27")
    ap.add_argument("--report-only", action="store_true")
    C.add_doc_flag(ap)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child[0], float(args.child[1]), args.child[2])))
        return ""
    info = C.machine_info()
    if not args.report_only:
        cache = ROOT / "outputs" / "bench_cache" / "identify"
        trees = [(str(C.git_snapshot(args.base, cache)), args.base)] if args.base else []
        trees.append((str(ROOT), "working tree " + C.git_head()))
        for p in [float(v) for v in args.exponents.split(",")]:
            for tree, tag in trees:
                out = subprocess.run([sys.executable, __file__, "--child", tree, str(p), tag],
                                     check=True, capture_output=True, text=True).stdout
                rec = json.loads(out.strip().splitlines()[-1])
                STORE.parent.mkdir(parents=True, exist_ok=True)
                with open(STORE, "a") as f:
                    f.write(json.dumps(rec) + "\n")
                print(f"[time] {tag} p={p}: {rec['cpu_s']:.1f} s CPU", flush=True)
    records = [json.loads(line) for line in STORE.read_text().splitlines()] \
        if STORE.exists() else []
    body = f"""
One two-amplitude 8-set-point joint identification (200 spp / 1 %, 600 periods, recorded
phase; the `identify_joint` section's "8 at two free amplitudes" rows), each in its own process,
one thread, `nice`; "CPU s": process CPU time of the fit (the period map compiled before the
clock); stage columns: CPU s inside the equation-error (EE) stages, the contact-onset (`a0`)
profile among them, the output-error (OE) stage and its exponent profile. CPU time under load
is inflated too (shared caches: the same code took 68 s at load ~8 last session, 86 s here).
Goal (issue 12): one identification <= 60 s. "code": the tree (a git revision, or the
working tree at that HEAD). Records in run order (`{STORE.relative_to(ROOT)}`).

{table(records)}
"""
    return C.write_section("identify_time", "Joint identification CPU time per stage "
                           "(`bench_identify_time.py`)", body, info, write=not args.no_doc)


if __name__ == "__main__":
    main()
