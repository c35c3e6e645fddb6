"""Diagnose one trace file and write ``report.json``, ``report.md`` and the figures.

:func:`diagnose_trace` is the one function behind ``scripts/diagnose.py``. It reads a
trace-format-v1 file **without its /labels group** and never interprets the file name, fits a
:class:`Diagnoser` and writes into ``out_dir`` (atomically: temporary sibling + rename):

``report.json``
    design.md section 3 (``cause``, ``confidence``, ``baseline``, ``extended``, ``gain``,
    ``candidates``, ``figures``) plus provenance, calibration, energies, warnings, runtime.
``report.md``
    The same for people, with the figures side by side (baseline left, extended right).
``*.png``
    :mod:`afmlearn.plots.diagnose`, unless ``figures=False``.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Any

import afmlearn
from afmlearn.io import jsonable, read_trace, write_json
from afmlearn.io._atomic import atomic_path
from afmlearn.preprocess import checked_row

from .diagnoser import Diagnoser
from .model import DiagnosisModel

__all__ = ["diagnose_trace", "report_record", "REPORT_FORMAT"]

REPORT_FORMAT = "afmlearn-diagnosis-report"

_CAUSE_TEXT = {
    "none": "the baseline (one mode, VdW-DMT sphere contact) explains the recording within "
            "its noise",
    "higher_mode": "a higher flexural eigenmode takes part in the motion",
    "viscoelastic": "the sample dissipates energy while indented, at a rate set by the "
                    "indentation speed (visco-elastic contact)",
    "long_range_damping": "energy is lost out of contact, by a damping that decays with the "
                          "gap (squeeze film, hydration or capillary layer)",
    "contact_geometry": "the force grows with indentation with an exponent other than the "
                        "sphere's 1.5 (cone-like tip)",
    "adhesion_hysteresis": "contact breaks later on retraction than it forms (a JKR-like "
                           "neck): rate-independent loss at pull-off",
    "electrostatic": "a long-range attraction decays slower than van der Waals "
                     "(electrostatics: bias or trapped charge)",
    "detector_nonlinearity": "the detector, not the cantilever, distorts the signal (an "
                             "output map with quadratic and cubic terms)",
}


def diagnose_trace(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                   row: int | None = None, diagnoser: Diagnoser | None = None,
                   figures: bool = True, qrnn: bool = True) -> dict[str, Any]:
    """Diagnose one trace file (one row of a sweep) and write the report.

    Parameters
    ----------
    path : str or os.PathLike
        Trace file, format v1. Its ``/labels`` group is never read.
    out_dir : str or os.PathLike
        Output folder (created if missing); existing report files are replaced.
    row : int, optional
        Row of a sweep, in ``[0, n_points)``; required for sweeps, None otherwise.
    diagnoser : Diagnoser, optional
        Settings (fitted in place); default ``Diagnoser()``.
    figures : bool
        Also write the PNG figures.
    qrnn : bool
        Also score the trace with the shipped QRNN mode-coupling checkpoint (issue 4) and
        report it as independent evidence for ``higher_mode`` (it does not change the cause).

    Returns
    -------
    dict
        The content of ``report.json`` plus ``diagnoser`` (the fitted :class:`Diagnoser`,
        not serialised).

    Raises
    ------
    afmlearn.io.TraceFormatError
        Missing file, not a trace, missing calibration attributes (a ValueError).
    afmlearn.preprocess.InputError
        NaN / inf, < 20 samples per period, too short, clipped (a ValueError).
    ValueError
        ``row`` missing for a sweep or out of range, a time-varying gap, bad settings.
    """
    t0 = time.perf_counter()
    path = Path(path)
    out = Path(out_dir)
    trace = read_trace(path)                          # labels=False: /labels never opened
    row = checked_row(trace, row)
    dg = diagnoser if diagnoser is not None else Diagnoser()
    if not isinstance(dg, Diagnoser):
        raise ValueError(f"diagnoser must be a Diagnoser, got {type(dg).__name__}")
    dg.fit(trace, row=row)
    out.mkdir(parents=True, exist_ok=True)
    figs: dict[str, Path] = {}
    if figures:
        from afmlearn.plots.diagnose import plot_all
        figs = plot_all(dg, out)
    rec = report_record(dg, input_path=path, row=row, figures=[p.name for p in figs.values()],
                        runtime_s=time.perf_counter() - t0)
    if qrnn:
        rec["qrnn_coupling"] = _qrnn_coupling(trace, row)
        for c in rec["candidates"]:
            q = rec["qrnn_coupling"]
            if c["cause"] == "higher_mode" and "score" in q:
                c["evidence"] += (f"; QRNN coupling score {q['score']:.2f} "
                                  f"({'coupled' if q['flag'] else 'not coupled'})")
    write_json(out / "report.json", rec)
    _write_text(out / "report.md", report_markdown(rec, figs))
    return {**rec, "diagnoser": dg}


def _qrnn_coupling(trace: Any, row: int | None) -> dict[str, Any]:
    """Mode-coupling score of the shipped QRNN checkpoint for this trace (or the reason not)."""
    try:
        from afmlearn.qrnn.infer import load_module, predict_trace
        module, run, used = load_module(None)
        s = predict_trace(trace, module, run)["summary"]
        t = s["traces"][0 if row is None else row]
        return {"score": float(t["score"]), "flag": bool(t["flag"]),
                "checkpoint": Path(used).name}
    except (ImportError, ValueError, RuntimeError) as err:  # no torch, or out of its range
        return {"unavailable": f"{type(err).__name__}: {err}"}


def _model_record(m: DiagnosisModel, nrmse: float, spectral: float | None, energy: float,
                  chi2: float | None) -> dict[str, Any]:
    sc = m.scales
    rec: dict[str, Any] = {"equation": m.equation(), "heldout_nrmse": float(nrmse),
                           "parameters": m.parameters(),
                           "energy_per_cycle_j": energy * sc.energy}
    if spectral is not None:
        rec["spectral_error"] = float(spectral)
    if chi2 is not None:
        rec["chi2"] = float(chi2)
    return rec


def report_record(dg: Diagnoser, *, input_path: str | os.PathLike[str], row: int | None,
                  figures: list[str], runtime_s: float) -> dict[str, Any]:
    """The JSON-able report (design.md section 3 keys first)."""
    cal = dg.calibrated_
    chosen = next((c for c in dg.candidates_ if c.cause == dg.cause_), None)
    base_chi2 = (chosen.chi2 + chosen.delta_chi2) if chosen else (
        dg.candidates_[0].chi2 + dg.candidates_[0].delta_chi2 if dg.candidates_ else None)
    return jsonable({
        "cause": dg.cause_,
        "confidence": dg.confidence_,
        "baseline": _model_record(dg.baseline_, dg.baseline_nrmse_,
                                  dg.spectral_error_["baseline"], dg.energy_["baseline"],
                                  base_chi2),
        "extended": {**_model_record(dg.extended_, dg.extended_nrmse_,
                                     dg.spectral_error_["extended"], dg.energy_["extended"],
                                     chosen.chi2 if chosen else base_chi2),
                     "cause": dg.cause_},
        "gain": dg.gain_,
        "candidates": [{"cause": c.cause, "gain": c.gain, "score": c.score,
                        "evidence": c.evidence, "delta_chi2": c.delta_chi2,
                        "threshold": c.threshold, "significant": c.significant,
                        "heldout_nrmse": c.heldout_nrmse, "n_parameters": c.n_parameters,
                        "equation": c.model.equation()} for c in dg.candidates_],
        "figures": figures,
        "format": REPORT_FORMAT,
        "afmlearn_version": afmlearn.__version__,
        "input": str(Path(input_path).resolve()),
        "row": row,
        "explanation": _CAUSE_TEXT.get(dg.cause_, ""),
        "energy_per_cycle_j": {k: v * cal.scales.energy for k, v in dg.energy_.items()},
        "free_trace_harmonics": dg.free_harmonics_,
        "noise": {"rms_m": dg.orbit_.noise_rms * cal.scales.length,
                  "n_harmonics": dg.orbit_.n_h},
        "split": {"heldout_start": dg.heldout_start_, "n_samples": cal.n_samples,
                  "heldout_fraction": dg.heldout_fraction},
        "calibration": {"spring_constant_n_per_m": cal.scales.spring_constant,
                        "resonance_frequency_hz": cal.scales.resonance_frequency,
                        "length_m": cal.scales.length, "quality_factor": cal.quality_factor,
                        "omega": cal.omega, "drive_amplitude": cal.drive_amplitude,
                        "drive_source": cal.drive_source, "excitation": cal.excitation,
                        "excitation_assumed": cal.excitation_assumed,
                        "samples_per_period": cal.samples_per_period},
        "thresholds": {"per_cause": dg.calibration_.thresholds,
                       "min_gain": dg.calibration_.min_gain,
                       "source": dg.calibration_.source},
        "warnings": list(dg.warnings_),
        "runtime_s": runtime_s,
    })


def report_markdown(rec: dict[str, Any], figs: dict[str, Path]) -> str:
    """``report.md``: the verdict, the two equations, the candidates table, the figures."""
    cause = rec["cause"]
    b, e = rec["baseline"], rec["extended"]
    lines = [f"# Diagnosis of `{Path(rec['input']).name}`", ""]
    if cause == "none":
        lines.append(f"**Cause: none** -- {rec['explanation']} (confidence "
                     f"{rec['confidence']:.2f}).")
    else:
        lines.append(f"**Cause: `{cause}`** -- {rec['explanation']}. Confidence "
                     f"{rec['confidence']:.2f}; the extended model cuts the held-out error by "
                     f"**{100 * rec['gain']:.1f} %** (NRMSE {b['heldout_nrmse']:.3g} -> "
                     f"{e['heldout_nrmse']:.3g}).")
    lines += ["", "| | baseline | extended |", "|---|---|---|",
              f"| equation | `{b['equation']}` | `{e['equation']}` |",
              f"| held-out NRMSE | {b['heldout_nrmse']:.4g} | {e['heldout_nrmse']:.4g} |",
              f"| spectral error | {b.get('spectral_error', math.nan):.4g} | "
              f"{e.get('spectral_error', math.nan):.4g} |",
              f"| energy to the sample per cycle [eV] | "
              f"{b['energy_per_cycle_j'] / 1.602176634e-19:.4g} | "
              f"{e['energy_per_cycle_j'] / 1.602176634e-19:.4g} |",
              "", f"Measured energy to the sample per cycle (drive minus lever damping): "
              f"{rec['energy_per_cycle_j']['measured'] / 1.602176634e-19:.4g} eV.", "",
              "## Every cause tested", "",
              "| cause | chi2 drop | null threshold | held-out gain | significant | evidence |",
              "|---|---|---|---|---|---|"]
    for c in rec["candidates"]:
        lines.append(f"| {c['cause']} | {c['delta_chi2']:.1f} | {c['threshold']:.1f} | "
                     f"{c['gain']:+.3f} | {'yes' if c['significant'] else 'no'} | "
                     f"{c['evidence']} |")
    lines += ["", "Evidence: drop of the output-error chi-square (orbit harmonics in units of "
              "their noise) when the cause's extension is added; significant above the "
              "threshold calibrated on null traces and with a held-out gain above "
              f"{rec['thresholds']['min_gain']:g}. Held-out: the last "
              f"{100 * rec['split']['heldout_fraction']:.0f} % of the periods, never fitted.",
              ""]
    q = rec.get("qrnn_coupling") or {}
    if "score" in q:
        lines += [f"QRNN mode-coupling score (issue 4's network, independent of the fits): "
                  f"{q['score']:.2f} ({'coupled' if q['flag'] else 'not coupled'}).", ""]
    if rec["warnings"]:
        lines += ["## Warnings", ""] + [f"- {w}" for w in rec["warnings"]] + [""]
    captions = {"residual": "Held-out deflection and residual",
                "orbit": "Phase-space orbit", "spectrum": "Spectrum (harmonics and between)",
                "force_gap": "Force vs gap, approach and retraction",
                "energy": "Energy dissipated per cycle", "candidates": "Evidence per cause"}
    if figs:
        lines += ["## Figures (baseline left, extended right)", ""]
        for k, pth in figs.items():
            lines += [f"### {captions.get(k, k)}", "", f"![{k}]({pth.name})", ""]
    lines.append(f"_afmlearn {rec['afmlearn_version']}, {rec['runtime_s']:.1f} s._")
    return "\n".join(lines) + "\n"


def _write_text(path: Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path
