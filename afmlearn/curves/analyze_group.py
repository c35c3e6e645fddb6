"""Joint analysis of curves of one tip: the functions behind ``analyze_curves.py joint=true``.

A folder's curves are grouped by their sub-folder (one tip and sample per folder, as the
Asylum export); each group is split into sets of ``group_size`` curves spanning its free
amplitudes (sorted by free amplitude, set ``k`` takes every ``n_sets``-th curve from the
``k``-th), and each set is diagnosed jointly (:class:`GroupDiagnoser`). The agreement of the
causes named by the sets of one group is the consistency check.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from afmlearn.io import write_json

from .analyze import _run_limited, _write_report, load_curve
from .group_diagnose import GroupDiagnoser

__all__ = ["analyze_folder_joint", "analyze_group", "split_sets"]

log = logging.getLogger(__name__)


def analyze_group(files: Sequence[str | os.PathLike[str]], out_dir: str | os.PathLike[str], *,
                  diagnoser: GroupDiagnoser | None = None,
                  figures: Callable[[GroupDiagnoser, Path], list[Path]] | None = None,
                  filename: str = "report.json") -> dict[str, Any]:
    """Diagnose the curves of ``files`` jointly (one lever and tip); write
    ``<out_dir>/report.json`` and figures.

    Parameters
    ----------
    files : sequence of path
        Curve files (trace format v1 with lock-in fields, or instrument files), >= 1; each
        file's first curve. Their k, f0 and Q must agree.
    out_dir : path
        Created if missing.
    diagnoser : GroupDiagnoser, optional
        Settings (each file's lock-in filter is used when the file states one).
    figures : callable, optional
        ``figures(fitted_diagnoser, out_dir) -> paths`` (``afmlearn.plots.curves_group``).

    Returns
    -------
    dict
        The report (``design.md`` section 3 keys plus ``group``: per-curve numbers with their
        ``file``).

    Raises
    ------
    ValueError
        No files, an unreadable file, or curves of different levers.
    """
    paths = [Path(f) for f in files]
    if not paths:
        raise ValueError("files: no curve files given")
    loaded = [load_curve(p) for p in paths]
    curves = [c for c, _ in loaded]
    diag = diagnoser if diagnoser is not None else GroupDiagnoser()
    lockins = [lk if lk is not None else diag.lockin for _, lk in loaded]
    diag.fit(curves, lockins=lockins)
    report = diag.report()
    for p, row in zip(paths, report["group"]["curves"], strict=True):
        row["file"] = p.name
    path = _write_report(report, report["group"], curves[0], diag, out_dir, figures=figures,
                         inputs=[p.name for p in paths], filename=filename)
    log.info("group of %d curves: %s written", len(paths), path)
    return report


def split_sets(lengths: Sequence[float], group_size: int) -> list[list[int]]:
    """Indices of sets of ``group_size`` curves, each spanning the free amplitudes.

    Sorted by free amplitude, set ``k`` of ``n_sets = max(1, n // group_size)`` takes the
    sorted curves ``k, k + n_sets, k + 2 n_sets, ...`` (at most ``group_size``; curves left
    over are not used).
    """
    if int(group_size) < 1:
        raise ValueError(f"group_size must be >= 1, got {group_size!r}")
    order = list(np.argsort(np.asarray(lengths, dtype=float), kind="stable"))
    n_sets = max(1, len(order) // int(group_size))
    return [[int(i) for i in order[k::n_sets][:group_size]] for k in range(n_sets)]


def analyze_folder_joint(folder: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                         make_diagnoser: Callable[[], GroupDiagnoser] = GroupDiagnoser,
                         group_size: int = 3, max_sets: int | None = None,
                         figures: Callable[[GroupDiagnoser, Path], list[Path]] | None = None,
                         time_limit_s: float | None = None, resume: bool = True
                         ) -> dict[str, Any]:
    """Every sub-folder of ``folder`` (a group: one tip) in sets of ``group_size`` curves,
    each set diagnosed jointly: ``<out_dir>/<group>/set_<k>/report.json`` and
    ``<out_dir>/joint_summary.json``.

    Parameters
    ----------
    group_size : int
        Curves per joint fit (>= 1; the leave-one-out gain needs >= 2).
    max_sets : int or None
        At most this many sets per group (spread over the group's sets).
    time_limit_s : float or None
        Wall-clock limit per set [s] (a forked child; None: in this process).
    resume : bool
        Reuse existing set reports.

    Returns
    -------
    dict
        ``groups``: per group its sets (files, cause, gain, seconds, load or error), cause
        counts, majority and agreement, median gain of the named sets.
    """
    folder = Path(folder)
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix in (".h5", ".ibw"))
    if not files:
        raise ValueError(f"trace: no .h5 or .ibw files in {folder}")
    if int(group_size) < 1:
        raise ValueError(f"group_size must be >= 1, got {group_size!r}")
    if max_sets is not None and int(max_sets) < 1:
        raise ValueError(f"max_sets must be >= 1 or None, got {max_sets!r}")
    if time_limit_s is not None and not time_limit_s > 0:
        raise ValueError(f"time_limit_s must be > 0 or None, got {time_limit_s!r}")
    out = Path(out_dir)
    by_group: dict[str, list[Path]] = {}
    for p in files:
        by_group.setdefault(p.parent.relative_to(folder).as_posix(), []).append(p)
    groups: dict[str, Any] = {}
    for g, members in sorted(by_group.items()):
        ok, lengths, refused = [], [], []
        for p in members:
            try:
                c, _ = load_curve(p)
            except ValueError as err:
                refused.append({"file": p.name, "error": str(err).splitlines()[0]})
                continue
            ok.append(p)
            lengths.append(c.length_m)
        sets = split_sets(lengths, group_size) if ok else []
        if max_sets is not None and len(sets) > max_sets:
            pick = np.unique(np.round(np.linspace(0, len(sets) - 1, max_sets)).astype(int))
            sets = [sets[i] for i in pick]
        rows = []
        for k, idx in enumerate(sets):
            sub = out / (g if g != "." else "") / f"set_{k:02d}"
            set_files = [ok[i] for i in idx]
            row: dict[str, Any] = {"set": k, "files": [p.name for p in set_files],
                                   "free_amplitudes_m": [lengths[i] for i in idx]}
            done = sub / "report.json"
            if not (resume and done.is_file()):
                if resume and (sub / "error.json").is_file():
                    rows.append({**row, **json.loads((sub / "error.json").read_text())})
                    continue
                err = _run_limited(_analyze_group_timed,
                                   (set_files, sub, make_diagnoser, figures), time_limit_s)
                if err is not None:
                    sub.mkdir(parents=True, exist_ok=True)
                    write_json(sub / "error.json", {"error": err})
                    rows.append({**row, "error": err})
                    log.warning("%s set %d: %s", g, k, err)
                    continue
            rep = json.loads(done.read_text())
            rows.append({**row, "cause": rep["cause"], "gain": rep["gain"],
                         "confidence": rep["confidence"],
                         "candidates": rep["candidates"],
                         "parameters": rep["extended"]["parameters"]["law"],
                         "length_m": rep["group"]["length_m"],
                         "seconds": rep.get("seconds"), "cpu_seconds": rep.get("cpu_seconds"),
                         "load": rep.get("load")})
            log.info("%s set %d: %s (gain %.3f)", g, k, rep["cause"], rep["gain"])
        groups[g] = {**_consistency(rows), "refused": refused, "sets": rows}
    summary = {"group_size": int(group_size), "groups": groups}
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "joint_summary.json", summary)
    return summary


def _consistency(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Cause counts, majority, agreement and median gain of a group's analysed sets."""
    ok = [r for r in rows if "cause" in r]
    causes: dict[str, int] = {}
    for r in ok:
        causes[r["cause"]] = causes.get(r["cause"], 0) + 1
    majority = max(sorted(causes), key=lambda c: causes[c]) if causes else None
    gains = np.array([r["gain"] for r in ok if r["cause"] != "none"], dtype=float)
    return {"n_sets": len(rows), "errors": len(rows) - len(ok), "causes": causes,
            "majority": majority,
            "agreement": causes[majority] / len(ok) if ok else float("nan"),
            "gain_positive": float(np.mean(gains > 0)) if gains.size else float("nan"),
            "median_gain": float(np.median(gains)) if gains.size else float("nan")}


def _analyze_group_timed(files: list[Path], sub: Path, make_diagnoser, figures) -> None:
    """``analyze_group`` plus wall-clock and CPU time and the load average in the report."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    c0 = time.process_time()
    rep = analyze_group(files, sub, diagnoser=make_diagnoser(), figures=figures)
    rep["seconds"] = time.perf_counter() - t0
    rep["cpu_seconds"] = time.process_time() - c0
    rep["load"] = load
    write_json(sub / "report.json", rep)
