"""Shared helpers of the benchmark scripts: machine info, timing, markdown, docs sections.

Every benchmark prints a markdown section and writes it into ``docs/benchmarks.md`` between
``<!-- BEGIN <name> -->`` and ``<!-- END <name> -->`` (other sections are left as they are).
"""

from __future__ import annotations

import datetime as _dt
import fcntl
import hashlib
import os
import platform
import re
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
if str(ROOT) not in sys.path:  # `python benchmarks/x.py` from the repository root
    sys.path.insert(0, str(ROOT))

_HEADER = """# Benchmarks

Measured by the scripts in `benchmarks/` (run all with `python benchmarks/run_all.py` or
`make bench`). Each section below is rewritten by its script; the numbers belong to the
machine, library versions and simulator source recorded in the section. The machine is shared
(2 cores), so the load average at the start of each run is recorded too: timings are the best of
several repeats, but a loaded machine still makes them pessimistic.
"""


def cpu_model() -> str:
    """CPU model name from ``/proc/cpuinfo`` (or ``platform.processor()``)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def source_hash(*relpaths: str) -> str:
    """Short SHA-256 of the given source files (identifies the simulator code measured)."""
    h = hashlib.sha256()
    for rel in relpaths:
        p = ROOT / rel
        h.update(p.read_bytes() if p.exists() else b"<missing>")
    return h.hexdigest()[:12]


def git_head() -> str:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "simulator"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return out.stdout.strip() + ("+uncommitted simulator changes" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def git_snapshot(rev: str, root: Path) -> Path:
    """``git archive`` of ``afmlearn/`` and ``simulator/`` at ``rev`` into ``root/<sha>``
    (made once; a ``COMMIT`` file names it and marks it complete), so that a benchmark can
    run the code of one commit beside the working tree. Returns the folder."""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short=10", rev],
                         capture_output=True, text=True, check=True).stdout.strip()
    dest = root / sha
    if not (dest / "COMMIT").exists():
        dest.mkdir(parents=True, exist_ok=True)
        arch = subprocess.run(["git", "-C", str(ROOT), "archive", sha, "afmlearn",
                               "simulator"], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=arch, check=True)
        (dest / "COMMIT").write_text(sha + "\n")
    return dest


def machine_info() -> dict[str, str]:
    """CPU, cores, library versions, date, load and simulator source fingerprint."""
    import numba
    import numpy
    import scipy

    try:
        load = "{:.2f} / {:.2f} / {:.2f}".format(*os.getloadavg())
    except OSError:
        load = "n/a"
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count() or 1
    return {
        "CPU": cpu_model(),
        "cores (usable)": f"{os.cpu_count()} ({usable})",
        "Python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "numba": f"{numba.__version__} (threads: {numba.config.NUMBA_NUM_THREADS})",
        "date": _dt.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        "load average at start (1/5/15 min)": load,
        "git": git_head(),
        "simulator/integrate/_kernel.py sha256": source_hash("simulator/integrate/_kernel.py"),
    }


def machine_block(info: dict[str, str]) -> str:
    return "\n".join(f"- {k}: {v}" for k, v in info.items())


def best_time(fn: Callable[[], object], *, repeat: int = 3, min_time: float = 0.0) -> float:
    """Best wall time [s] of ``repeat`` calls (at least one; more while under ``min_time``)."""
    best = float("inf")
    total = 0.0
    k = 0
    while k < repeat or total < min_time:
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        best = min(best, dt)
        total += dt
        k += 1
        if k >= 20:
            break
    return best


def md_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table."""
    def cell(v: object) -> str:
        return v if isinstance(v, str) else f"{v}"

    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    out += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(out)


def fmt(x: float, digits: int = 3) -> str:
    """Compact number formatting (3 significant digits by default)."""
    if x == 0 or x != x:
        return f"{x:g}"
    return f"{x:.{digits}g}" if 1e-3 <= abs(x) < 1e6 else f"{x:.{digits - 1}e}"


def command_line() -> str:
    script = Path(sys.argv[0]).resolve()
    try:
        rel = script.relative_to(ROOT)
    except ValueError:
        rel = script
    args = " ".join(sys.argv[1:])
    return f"cd {ROOT.name} && python {rel}{(' ' + args) if args else ''}"


def add_doc_flag(parser) -> None:
    """``--no-doc``: print the section only (smoke runs must not overwrite the results)."""
    parser.add_argument("--no-doc", action="store_true",
                        help="print the results without updating docs/benchmarks.md")


def write_section(name: str, title: str, body: str, info: dict[str, str],
                  *, command: str | None = None, write: bool = True) -> str:
    """Print the section and write it into ``docs/benchmarks.md`` (replacing an old one)."""
    cmd = command or command_line()
    text = (f"<!-- BEGIN {name} -->\n## {title}\n\n"
            f"Command: `{cmd}`\n\n{machine_block(info)}\n\n{body.strip()}\n<!-- END {name} -->")
    print(text)
    if not write:
        return text
    DOC.parent.mkdir(parents=True, exist_ok=True)
    pat = re.compile(rf"<!-- BEGIN {re.escape(name)} -->.*?<!-- END {re.escape(name)} -->",
                     re.S)
    # benchmarks may finish concurrently: read-modify-write under a lock, then an atomic
    # rename, so no section is lost and a reader never sees a half-written file
    with open(DOC.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        old = DOC.read_text() if DOC.exists() else _HEADER
        new = (pat.sub(lambda _m: text, old) if pat.search(old)
               else old.rstrip() + "\n\n" + text + "\n")
        tmp = DOC.with_suffix(".md.tmp")
        tmp.write_text(new)
        os.replace(tmp, DOC)
    return text
