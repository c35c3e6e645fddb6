"""RK4 kernel throughput: integration steps per second, single trajectory and batched.

Problems: the 1-mode and the 2-mode VdW--DMT tapping system of ``_systems.py`` (Table 3.B.1,
base excitation) at ``Omega = 0.998`` on its steady tapping orbit (about one impact per period,
i.e. two located contact events per period). The step is the thesis sample interval
``dt = 2 pi / 1500`` with one RK4 step per sample (``RK4(substeps=1)``), so steps = samples.

Numba compile time is measured in fresh subprocesses: once with an empty cache directory
(``NUMBA_CACHE_DIR`` pointed at a temporary folder: a cold compile) and once with the
project's cache (load from cache); imports are excluded from both.

Run: ``python benchmarks/bench_integrator.py [--quick]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import _common as C  # first: puts the repository root on sys.path
import numpy as np
from _systems import DT, OMEGA_BENCH, VDW_C1, system, tapping_state

from simulator import RK4

_FIRST_CALL = r"""
import time, sys
sys.path.insert(0, {root!r}); sys.path.insert(0, {bench!r})
from _systems import system, DT
from simulator import RK4, State
s = system({m})
st = State.free_orbit(s, omega=[1.0])
t = time.perf_counter()
RK4(substeps=1).run(s, st, omega=1.0, n_samples=10, dt=DT)
print(time.perf_counter() - t)
"""


def first_call_seconds(n_modes: int, *, cold: bool) -> float:
    """Wall time of the first ``RK4.run`` in a fresh interpreter (imports excluded)."""
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        if cold:
            env["NUMBA_CACHE_DIR"] = tmp
        code = _FIRST_CALL.format(root=str(C.ROOT), bench=str(C.ROOT / "benchmarks"), m=n_modes)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                             text=True, check=True, timeout=1800)
    return float(out.stdout.strip().splitlines()[-1])


def throughput(n_modes: int, batch: int, *, steps_target: float, repeat: int) -> dict:
    s = system(n_modes)
    st = tapping_state(s, batch=batch, periods=300)
    rk = RK4(substeps=1)
    n = max(1000, int(steps_target / batch))
    rk.run(s, st, omega=OMEGA_BENCH, n_samples=1000, dt=DT)  # warm-up: compile / cache load
    t = C.best_time(lambda: rk.run(s, st, omega=OMEGA_BENCH, n_samples=n, dt=DT),
                    repeat=repeat)
    seg = rk.run(s, st, omega=OMEGA_BENCH, n_samples=n, dt=DT)
    events = int(np.count_nonzero(np.diff(seg.contact, axis=1))) / batch
    steps = batch * n
    return {"steps/s": steps / t, "ns/step": 1e9 * t / steps, "time": t, "n": n,
            "events/traj": events, "contact": float(seg.contact.mean())}


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer steps, no compile-time runs")
    C.add_doc_flag(ap)
    args = ap.parse_args(argv)
    info = C.machine_info()
    target = 1e6 if args.quick else 8e6
    repeat = 2 if args.quick else 3
    rows = []
    for m in (1, 2):
        base = None
        for b in (1, 2, 8, 32):
            r = throughput(m, b, steps_target=target, repeat=repeat)
            base = base or r["steps/s"]
            rows.append([f"{m}-mode", b, f"{r['steps/s'] / 1e6:.2f}", f"{r['ns/step']:.0f}",
                         f"{r['steps/s'] / base:.2f}", f"{r['n']:,}",
                         f"{r['events/traj'] / (r['n'] / 1500):.2f}",
                         f"{r['contact']:.3f}", f"{r['time']:.2f}"])
            print(rows[-1], flush=True)
    body = ["Classical RK4, one step per sample at `dt = 2 pi / 1500`, steady tapping orbit "
            f"at `Omega = {OMEGA_BENCH}` (Table 3.B.1 system, C1 = {VDW_C1:g}). Steps per "
            "second count trajectory steps summed over the batch (B trajectories advance in "
            "parallel over numba threads). Best of "
            f"{repeat} runs after a warm-up call.", "",
            C.md_table(["model", "batch B", "M steps/s", "ns/step (per traj.)",
                        "speed-up vs B=1", "samples per traj.", "contact events per period",
                        "contact fraction", "best wall [s]"], rows)]
    if not args.quick:
        comp = []
        for m in (1, 2):
            cold = first_call_seconds(m, cold=True)
            warm = first_call_seconds(m, cold=False)
            comp.append([f"{m}-mode", f"{cold:.1f}", f"{warm:.2f}"])
            print(comp[-1], flush=True)
        body += ["", "First `RK4.run` call in a fresh interpreter (imports excluded): numba "
                 "compile from an empty cache vs. load from the on-disk cache "
                 "(`cache=True`). Neither is included in the throughput above.", "",
                 C.md_table(["model", "cold compile [s]", "cached load [s]"], comp)]
    return C.write_section("bench_integrator", "Integrator throughput (`bench_integrator.py`)",
                           "\n".join(body), info, write=not args.no_doc)


if __name__ == "__main__":
    t0 = time.time()
    main()
    print(f"(total {time.time() - t0:.0f} s)")
