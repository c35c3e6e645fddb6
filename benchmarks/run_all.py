"""Run every benchmark in turn; each refreshes its own section of ``docs/benchmarks.md``.

Run: ``python benchmarks/run_all.py [--quick]`` (``--quick``: reduced sizes, a smoke test
that prints but does not touch ``docs/benchmarks.md``). The sweet-spot study
(``sweet_spot.py``) is not a benchmark and is run separately.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

FULL = [
    ["bench_integrator.py"],
    ["bench_vs_solve_ivp.py"],
    ["bench_thesis_sweep.py"],
    ["bench_identify_speed.py"],
    ["bench_identify_accuracy.py"],
    ["bench_qrnn_speed.py"],
    ["bench_qrnn_accuracy.py"],
    ["bench_diagnose.py", "--calibrate"],
    ["bench_fm_inversion.py"],
]
QUICK = [
    ["bench_integrator.py", "--quick", "--no-doc"],
    ["bench_vs_solve_ivp.py", "--periods", "5", "--no-rk45", "--no-doc"],
    ["bench_thesis_sweep.py", "--points", "21", "--samples", "5000", "--baseline-freqs", "3",
     "--baseline-periods", "3", "--no-doc"],
    ["bench_identify_speed.py", "--quick"],
    ["bench_identify_accuracy.py", "--quick"],
    ["bench_qrnn_accuracy.py", "--quick"],
    ["bench_diagnose.py", "--quick"],
]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    failed = []
    for cmd in QUICK if args.quick else FULL:
        t0 = time.time()
        print(f"=== {' '.join(cmd)}", flush=True)
        rc = subprocess.call([sys.executable, str(HERE / cmd[0]), *cmd[1:]], cwd=HERE.parent)
        print(f"=== {cmd[0]}: exit {rc}, {time.time() - t0:.0f} s", flush=True)
        if rc:
            failed.append(cmd[0])
    if failed:
        print("failed:", ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
