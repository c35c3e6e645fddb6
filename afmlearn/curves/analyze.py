"""Analyse one lock-in curve file: the function behind ``scripts/analyze_curves.py``."""

from __future__ import annotations

import json
import logging
import math
import multiprocessing as mp
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from afmlearn.io import read_trace, write_json
from afmlearn.io.instruments import is_instrument_file, open_traces
from simulator.lockin import LockIn

from .curve import Curve
from .diagnose import CurveDiagnoser
from .law import CurveLaw

__all__ = ["analyze_curve", "analyze_folder", "damping_terms_si", "identify_curve",
           "is_curve_file", "load_curve"]

log = logging.getLogger(__name__)

#: lock-in filter order assumed when a file states only the bandwidth
DEFAULT_ORDER = 4


def load_curve(path: str | os.PathLike[str], *, index: int = 0) -> tuple[Curve, LockIn | None]:
    """The curve ``index`` of a trace file (.h5, labels never read) or an instrument file.

    Returns the dimensionless :class:`Curve` and the lock-in filter the file states
    (``lockin_bandwidth_hz``, order :data:`DEFAULT_ORDER`), or None when it states none.

    Raises
    ------
    ValueError
        For a missing or unreadable file, one that is not a lock-in curve, or a bad index.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"trace: no such file {p}")
    traces = open_traces(p) if is_instrument_file(p) else [read_trace(p)]
    if not 0 <= index < len(traces):
        raise ValueError(f"index must be in [0, {len(traces)}) for {p.name}, got {index}")
    trace = traces[index]
    curve = Curve.from_trace(trace)
    bw = getattr(trace, "lockin_bandwidth_hz", None)
    lockin = None
    if bw is not None and math.isfinite(float(bw)) and 0 < bw < 0.5 * curve.resonance_frequency_hz:
        lockin = LockIn(bandwidth=float(bw) / curve.resonance_frequency_hz,
                        order=DEFAULT_ORDER, output_interval=float(curve.tau[1] - curve.tau[0]))
    return curve, lockin


def is_curve_file(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` holds lock-in curves without a deflection record (an Asylum AM curve
    ``.ibw``, a trace file with ``amplitude_m``/``phase_rad`` and no ``deflection_m``).

    False for anything else, including files that cannot be read (the caller's own reader then
    reports what is wrong with them).
    """
    p = Path(path)
    if not p.is_file():
        return False
    try:
        traces = open_traces(p) if is_instrument_file(p) else [read_trace(p)]
    except (ValueError, OSError):
        return False
    return bool(traces) and all(t.is_curves and t.deflection_m is None for t in traces)


def identify_curve(trace: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                   diagnoser: CurveDiagnoser | None = None, index: int = 0,
                   figures: Callable[[CurveDiagnoser, Path], list[Path]] | None = None
                   ) -> dict[str, Any]:
    """Fit the baseline law alone to one curve's approach; write ``<out_dir>/result.json``.

    What ``scripts/identify.py`` does with a lock-in curve: the equation of the tip--sample
    law (VdW--DMT sphere, :class:`CurveFitter` through a :class:`CurveDiagnoser` without
    hypotheses), its held-out error on the retraction, and figures.

    Parameters
    ----------
    trace, out_dir, index, figures
        As :func:`analyze_curve`.
    diagnoser : CurveDiagnoser, optional
        Settings; its ``hypotheses`` are ignored (none are fitted).

    Returns
    -------
    dict
        ``equation`` (SI: nN, nm), ``parameters`` (dimensionless fitted values),
        ``heldout_nrmse`` (retraction), ``chi2``, ``n_fit``, ``curve`` (as the report's),
        ``figures``, ``input``.
    """
    diag = diagnoser if diagnoser is not None else CurveDiagnoser()
    diag.hypotheses = ()
    rep = analyze_curve(trace, out_dir, diagnoser=diag, index=index, figures=figures,
                        filename="result.json", build=_identify_result)
    return rep


def _identify_result(diag: CurveDiagnoser) -> dict[str, Any]:
    rep = diag.report()
    base = rep["baseline"]
    return {"equation": base["equation"], "parameters": base["parameters"],
            "heldout_nrmse": base["heldout_nrmse"], "chi2": base["chi2"],
            "n_fit": base["n_fit"], "curve": rep["curve"], "figures": []}


def analyze_curve(trace: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                  diagnoser: CurveDiagnoser | None = None, index: int = 0,
                  figures: Callable[[CurveDiagnoser, Path], list[Path]] | None = None,
                  filename: str = "report.json",
                  build: Callable[[CurveDiagnoser], dict[str, Any]] | None = None
                  ) -> dict[str, Any]:
    """Diagnose one curve and write ``<out_dir>/report.json`` (and figures).

    Parameters
    ----------
    trace : path
        Trace file (format v1 with lock-in fields) or instrument file (Asylum ``.ibw`` ...).
    out_dir : path
        Created if missing.
    diagnoser : CurveDiagnoser, optional
        Settings (its ``lockin`` is replaced by the file's filter when the file states one).
    index : int
        Curve of a file holding several.
    figures : callable, optional
        ``figures(fitted_diagnoser, out_dir) -> paths`` (``afmlearn.plots.curves``).
    filename : str
        Name of the JSON file written in ``out_dir``.
    build : callable, optional
        ``build(fitted_diagnoser) -> dict``: the record to write (default: its report).

    Returns
    -------
    dict
        The report (``design.md`` section 3 keys plus ``curve``).
    """
    curve, lockin = load_curve(trace, index=index)
    diag = diagnoser if diagnoser is not None else CurveDiagnoser()
    if lockin is not None:
        diag.lockin = lockin
    diag.fit(curve)
    if build is None:
        report = diag.report()
        report["curve"]["damping_terms"] = damping_terms_si(diag.extended_.law_, curve)
    else:
        report = build(diag)
    path = _write_report(report, report["curve"], curve, diag, out_dir, figures=figures,
                         inputs=Path(trace).name, filename=filename)
    log.info("%s: %s written", Path(trace).name, path)
    return report


def damping_terms_si(law: CurveLaw, curve: Curve) -> list[dict[str, Any]]:
    """The law's damping terms in SI, for the report (``long_range_damping`` has two).

    Returns
    -------
    list of dict
        One per term that is on (``CurveLaw.damping_terms``): ``term`` (``"near"``: the
        near-contact term ``damping``; ``"far"``: the far-field one), ``coefficient_n_s_per_m``
        (``c`` of ``-c exp(-z / z_b) z'``), ``decay_length_m`` (``z_b``) and
        ``times_lever_damping`` (``c`` over the lever's own damping ``k / (omega0 Q)``).
    """
    k = curve.spring_constant_n_per_m
    w0 = 2.0 * math.pi * curve.resonance_frequency_hz
    return [{"term": name, "coefficient_n_s_per_m": c * k / w0,
             "decay_length_m": zb * curve.length_m,
             "times_lever_damping": c * curve.quality_factor}
            for name, c, zb in law.damping_terms()]


def _write_report(report: dict[str, Any], section: dict[str, Any], curve: Any, diag: Any,
                  out_dir: str | os.PathLike[str], *, figures: Callable[..., Any] | None,
                  inputs: Any, filename: str) -> Path:
    """Complete a curve or group report and write it (the one writer of both analyses).

    ``section`` (``report["curve"]`` or ``report["group"]``) receives the lever's k [N/m],
    f0 [Hz] and Q from ``curve``; ``figures(diag, out_dir)`` paths are stored relative to
    ``out_dir``; ``inputs`` (file name or names) under ``"input"``. Returns the JSON path.
    """
    section.update(spring_constant_n_per_m=curve.spring_constant_n_per_m,
                   resonance_frequency_hz=curve.resonance_frequency_hz,
                   quality_factor=curve.quality_factor)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if figures is not None:
        report["figures"] = [os.path.relpath(f, out) for f in figures(diag, out)]
    report["input"] = inputs
    write_json(out / filename, report)
    return out / filename


def analyze_folder(folder: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                   make_diagnoser: Callable[[], CurveDiagnoser] = CurveDiagnoser,
                   figures: Callable[[CurveDiagnoser, Path], list[Path]] | None = None,
                   summary_figure: Callable[[list[dict], Path], Path] | None = None,
                   time_limit_s: float | None = None, resume: bool = True
                   ) -> dict[str, Any]:
    """Every curve file under ``folder`` (recursively, sorted): ``<out_dir>/<relative path
    without suffix>/report.json`` each and ``<out_dir>/summary.json`` (cause counts, gains,
    fitted parameters, time per curve).

    Each curve runs in a child process (forked) under ``time_limit_s``: a file that cannot be
    analysed, crashes its process or runs out of time is listed with its one-line error
    (``timeout after ... s``), never aborts or hangs the batch. With ``resume``, a curve whose
    ``report.json`` exists is read back, not analysed again (a killed batch continues).

    Parameters
    ----------
    time_limit_s : float or None
        Wall-clock limit per curve [s] (None: no limit, run in this process).
    resume : bool
        Reuse existing reports.

    Rows carry ``file`` (relative path), ``group`` (its folder relative to ``folder``),
    ``seconds`` (wall clock of the analysis) and ``load`` (1-minute load average at its
    start) besides the report's numbers.
    """
    folder = Path(folder)
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix in (".h5", ".ibw"))
    if not files:
        raise ValueError(f"trace: no .h5 or .ibw files in {folder}")
    if time_limit_s is not None and not time_limit_s > 0:
        raise ValueError(f"time_limit_s must be > 0 or None, got {time_limit_s!r}")
    out = Path(out_dir)
    rows: list[dict[str, Any]] = []
    for p in files:
        rel = p.relative_to(folder)
        sub = out / rel.with_suffix("")
        row: dict[str, Any] = {"file": rel.as_posix(), "group": rel.parent.as_posix()}
        done = sub / "report.json"
        if not (resume and done.is_file()):
            if (sub / "error.json").is_file() and resume:
                rows.append({**row, **json.loads((sub / "error.json").read_text())})
                continue
            err = _run_one(p, sub, make_diagnoser, figures, time_limit_s)
            if err is not None:
                rec = {"error": err}
                sub.mkdir(parents=True, exist_ok=True)
                write_json(sub / "error.json", rec)
                rows.append({**row, **rec})
                log.warning("%s: %s", rel, err)
                continue
        rep = json.loads(done.read_text())
        rows.append({**row, **_row(rep)})
    ok = [r for r in rows if "cause" in r]
    summary = {"n_files": len(files), "n_analysed": len(ok), **group_summary(rows),
               "groups": {g: group_summary([r for r in rows if r["group"] == g])
                          for g in sorted({r["group"] for r in rows})},
               "curves": rows, "figures": []}
    out.mkdir(parents=True, exist_ok=True)
    if summary_figure is not None and ok:
        summary["figures"] = [os.path.relpath(summary_figure(ok, out), out)]
    write_json(out / "summary.json", summary)
    return summary


def group_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Consistency of a group of curves (``analyze_folder`` rows).

    Returns
    -------
    dict
        ``n``; ``errors`` (timeouts, crashes, unreadable files); ``causes`` (counts);
        ``majority`` (the most frequent cause) and ``agreement`` (its fraction of the analysed
        curves); ``n_named`` (curves with a cause), ``gain_positive`` (fraction of those whose
        extended model predicts the retraction better than the baseline), ``median_gain``
        (over them); ``seconds`` (median, max wall clock per curve), ``cpu_seconds`` (median
        CPU time per curve) and ``load`` (median
        1-minute load average during the runs).
    """
    ok = [r for r in rows if "cause" in r]
    causes: dict[str, int] = {}
    for r in ok:
        causes[r["cause"]] = causes.get(r["cause"], 0) + 1
    majority = max(sorted(causes), key=lambda c: causes[c]) if causes else None
    named = [r for r in ok if r["cause"] != "none"]
    gains = np.array([r["gain"] for r in named], dtype=float)
    secs = np.array([r["seconds"] for r in ok if r.get("seconds") is not None], dtype=float)
    cpu = np.array([r["cpu_seconds"] for r in ok if r.get("cpu_seconds") is not None],
                   dtype=float)
    loads = np.array([r["load"] for r in ok if r.get("load") is not None], dtype=float)
    return {"n": len(rows), "errors": len(rows) - len(ok), "causes": causes,
            "majority": majority,
            "agreement": causes[majority] / len(ok) if ok else float("nan"),
            "n_named": len(named),
            "gain_positive": float(np.mean(gains > 0)) if named else float("nan"),
            "median_gain": float(np.median(gains)) if named else float("nan"),
            "seconds": ([float(np.median(secs)), float(np.max(secs))] if secs.size
                        else None),
            "cpu_seconds": float(np.median(cpu)) if cpu.size else None,
            "load": float(np.median(loads)) if loads.size else None}


def _row(rep: dict[str, Any]) -> dict[str, Any]:
    """The numbers of one report that the folder summary lists."""
    return {"cause": rep["cause"], "gain": rep["gain"], "confidence": rep["confidence"],
            "free_amplitude_m": rep["curve"]["free_amplitude_m"],
            "adhesion_force_n": rep["curve"]["adhesion_force_n"],
            "spring_constant_n_per_m": rep["curve"].get("spring_constant_n_per_m"),
            "resonance_frequency_hz": rep["curve"].get("resonance_frequency_hz"),
            "heldout_nrmse_baseline": rep["baseline"]["heldout_nrmse"],
            "heldout_nrmse_extended": rep["extended"]["heldout_nrmse"],
            "parameters": rep["extended"]["parameters"],
            "baseline_parameters": rep["baseline"]["parameters"],
            "seconds": rep.get("seconds"), "cpu_seconds": rep.get("cpu_seconds"),
            "load": rep.get("load")}


def _analyze_timed(path: Path, sub: Path, make_diagnoser, figures) -> None:
    """``analyze_curve`` plus its wall-clock time and the load average in the report."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    c0 = time.process_time()
    rep = analyze_curve(path, sub, diagnoser=make_diagnoser(), figures=figures)
    rep["seconds"] = time.perf_counter() - t0
    rep["cpu_seconds"] = time.process_time() - c0  # this process's own CPU (the forked child)
    rep["load"] = load
    write_json(sub / "report.json", rep)


def _child(target, args, conn) -> None:  # pragma: no cover (child)
    try:
        target(*args)
        conn.send(None)
    except Exception as err:  # noqa: BLE001 - any failure of one curve is recorded, not raised
        conn.send(f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}")


def _run_one(path: Path, sub: Path, make_diagnoser, figures, time_limit_s) -> str | None:
    """Analyse one curve (in a child process under the time limit); the error line or None."""
    return _run_limited(_analyze_timed, (path, sub, make_diagnoser, figures), time_limit_s)


def _run_limited(target: Callable[..., None], args: tuple, time_limit_s: float | None
                 ) -> str | None:
    """``target(*args)`` in a forked child under ``time_limit_s`` (None: in this process,
    ValueErrors caught); the one-line error or None."""
    if time_limit_s is None:
        try:
            target(*args)
        except ValueError as err:
            return str(err).splitlines()[0]
        return None
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(target, args, send))
    proc.start()
    send.close()
    try:
        if recv.poll(time_limit_s):
            msg = recv.recv()
            proc.join(10.0)
            return msg
        return f"timeout after {time_limit_s:g} s"
    except EOFError:
        proc.join(10.0)
        return f"the analysis process died (exit code {proc.exitcode})"
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
        recv.close()
