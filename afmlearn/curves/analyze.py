"""Analyse one lock-in curve file: the function behind ``scripts/analyze_curves.py``."""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from afmlearn.io import read_trace, write_json
from afmlearn.io.instruments import is_instrument_file, open_traces
from simulator.lockin import LockIn

from .curve import Curve
from .diagnose import CurveDiagnoser

__all__ = ["analyze_curve", "analyze_folder", "identify_curve", "is_curve_file", "load_curve"]

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
    report = diag.report() if build is None else build(diag)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if figures is not None:
        report["figures"] = [os.path.relpath(f, out) for f in figures(diag, out)]
    report["input"] = Path(trace).name
    write_json(out / filename, report)
    log.info("%s: %s written", Path(trace).name, out / filename)
    return report


def analyze_folder(folder: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                   make_diagnoser: Callable[[], CurveDiagnoser] = CurveDiagnoser,
                   figures: Callable[[CurveDiagnoser, Path], list[Path]] | None = None,
                   summary_figure: Callable[[list[dict], Path], Path] | None = None,
                   ) -> dict[str, Any]:
    """Every curve file of ``folder`` (sorted): ``<out_dir>/<stem>/report.json`` each and
    ``<out_dir>/summary.json`` (cause counts, gains, fitted parameters per curve).

    A file that cannot be analysed is listed with its one-line error, never aborts the batch.
    """
    folder = Path(folder)
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix in (".h5", ".ibw"))
    if not files:
        raise ValueError(f"trace: no .h5 or .ibw files in {folder}")
    out = Path(out_dir)
    rows: list[dict[str, Any]] = []
    for p in files:
        try:
            rep = analyze_curve(p, out / p.stem, diagnoser=make_diagnoser(), figures=figures)
        except ValueError as err:
            rows.append({"file": p.name, "error": str(err).splitlines()[0]})
            continue
        ext = rep["extended"]["parameters"]
        rows.append({"file": p.name, "cause": rep["cause"], "gain": rep["gain"],
                     "confidence": rep["confidence"],
                     "free_amplitude_m": rep["curve"]["free_amplitude_m"],
                     "adhesion_force_n": rep["curve"]["adhesion_force_n"],
                     "heldout_nrmse_baseline": rep["baseline"]["heldout_nrmse"],
                     "heldout_nrmse_extended": rep["extended"]["heldout_nrmse"],
                     "parameters": ext})
    done = [r for r in rows if "cause" in r]
    causes = sorted({r["cause"] for r in done})
    summary = {"n_files": len(files), "n_analysed": len(done),
               "causes": {c: sum(r["cause"] == c for r in done) for c in causes},
               "curves": rows, "figures": []}
    out.mkdir(parents=True, exist_ok=True)
    if summary_figure is not None and done:
        summary["figures"] = [os.path.relpath(summary_figure(done, out), out)]
    write_json(out / "summary.json", summary)
    return summary
