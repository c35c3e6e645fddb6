"""Diagnose one trace file and write ``report.json``, ``report.md`` and the figures.

:func:`diagnose_trace` is the one function behind ``scripts/diagnose.py``. It reads a
trace-format-v1 file **without its /labels group** and never interprets the file name, fits a
:class:`Diagnoser` to the file's experiment (a set-point series: every row; one steady record
or one row of a sweep: an experiment of one) and writes into ``out_dir`` (atomically:
temporary sibling + rename):

``report.json``
    design.md section 3 (``cause``, ``confidence``, ``baseline``, ``extended``, ``gain``,
    ``candidates``, ``causes``, ``figures``; ``causes`` the ones the backward check kept)
    plus ``dropped_causes`` (named step by step, then dropped: cause, chi2 rise on removal,
    threshold, held-out gain, the gain that decided with its basis when the cause measures
    its own, reason), ``not_separated`` (per kept cause, the candidates of
    its step the data do not separate from it: chi2 drops, their noise, held-out NRMSE and
    the per-set-point sign test; :mod:`.ties`), the held-out NRMSE per observation
    (``observations``), the held-out design, the contact exponent's interval, provenance,
    calibration, energies, warnings, runtime.
``report.md``
    The same for people, with the figures side by side (baseline left, extended right).
``*.png``
    Drawn by the ``figures`` callable the caller passes (the script passes
    ``afmlearn.plots.diagnose.plot_all``; this package never imports the plots).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import afmlearn
from afmlearn.identify.fixed_exponent import SPHERE_EXPONENT
from afmlearn.io import jsonable, read_trace, write_json
from afmlearn.io._atomic import atomic_path
from afmlearn.preprocess import checked_row

from .backward import Removal
from .diagnoser import Diagnoser
from .hypotheses import default_hypotheses
from .hypotheses.contact_geometry import exponent_summary
from .model import DiagnosisModel
from .observation import read_experiment
from .ties import Tie

__all__ = ["diagnose_trace", "report_record", "REPORT_FORMAT", "FigureWriter"]

REPORT_FORMAT = "afmlearn-diagnosis-report"

#: ``decision_gain_basis`` of a gain measured on a cause's own signature (a candidate's, and a
#: kept or dropped cause's in the backward check); absent: the NRMSE gain decided
OWN_GAIN_BASIS = "the hypothesis' own held-out signature (AbstractHypothesis.heldout_gain)"

#: ``figures(diagnoser, out_dir) -> {name: path}``: draws the report's figures
FigureWriter = Callable[[Diagnoser, Path], dict[str, Path]]

_NONE_TEXT = ("the baseline (one mode, VdW-DMT sphere contact) explains the recording within "
              "its noise")


def diagnose_trace(path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
                   out_dir: str | os.PathLike[str], *,
                   row: int | None = None, diagnoser: Diagnoser | None = None,
                   figures: FigureWriter | None = None) -> dict[str, Any]:
    """Diagnose one trace file (its experiment, or one row) and write the report.

    Parameters
    ----------
    path : str or os.PathLike, or a sequence of them
        Trace file, format v1. Its ``/labels`` group is never read. Several files of one
        tip (e.g. set-point series at two free amplitudes) are one experiment
        (:func:`~afmlearn.diagnose.observation.read_experiment`; ``row`` must be None);
        the report's ``input`` is then the list of files.
    out_dir : str or os.PathLike
        Output folder (created if missing); existing report files are replaced.
    row : int, optional
        Diagnose one row: required for a sweep (in ``[0, n_points)``); for a set-point
        series it picks one set-point (default: all of them, fitted jointly).
    diagnoser : Diagnoser, optional
        Settings (fitted in place); default ``Diagnoser()``.
    figures : callable, optional
        ``figures(diagnoser, out_dir) -> {name: path}`` draws the figures (e.g.
        ``afmlearn.plots.diagnose.plot_all``); None: no figures.

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
        ``row`` missing for a sweep or out of range, bad settings, files that are not one
        cantilever's.
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    data: Any
    if isinstance(path, (str, os.PathLike)):
        path = Path(path)
        data = read_trace(path)                       # labels=False: /labels never opened
        if data.is_sweep or not data.has_rows:
            row = checked_row(data, row)
        elif row is not None and (isinstance(row, bool) or not isinstance(row, int)
                                  or not 0 <= row < data.n_points):
            raise ValueError(f"row must be null (every set-point) or an integer in "
                             f"[0, {data.n_points}), got {row!r}")
    else:                                             # files of one tip: one experiment
        if row is not None:
            raise ValueError(f"row must be null when several files are diagnosed, got {row!r}")
        data = read_experiment(path)                  # labels never opened
    dg = diagnoser if diagnoser is not None else Diagnoser()
    if not isinstance(dg, Diagnoser):
        raise ValueError(f"diagnoser must be a Diagnoser, got {type(dg).__name__}")
    if figures is not None and not callable(figures):
        raise ValueError(f"figures must be None or a callable (diagnoser, out_dir) -> "
                         f"dict, got {figures!r}")
    dg.fit(data, row=row)
    out.mkdir(parents=True, exist_ok=True)
    figs: dict[str, Path] = figures(dg, out) if figures is not None else {}
    paths = [path] if isinstance(path, Path) else [Path(p) for p in path]
    rec = report_record(dg, input_path=paths[0], row=row,
                        figures=[p.name for p in figs.values()],
                        runtime_s=time.perf_counter() - t0)
    if not isinstance(path, Path):
        rec["input"] = [str(p.resolve()) for p in paths]
    write_json(out / "report.json", rec)
    _write_text(out / "report.md", report_markdown(rec, figs))
    return {**rec, "diagnoser": dg}


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
    hyps = {h.cause: h for h in (dg.hypotheses or default_hypotheses())}
    base_chi2 = (dg.candidates_[0].chi2 + dg.candidates_[0].delta_chi2
                 if dg.candidates_ else None)
    final_chi2 = dg.extended_chi2_ if dg.causes_ else base_chi2
    details = {c.cause: c.details for c in dg.candidates_}
    qrnn = details.get("higher_mode", {}).get("qrnn_coupling")
    length = cal.scales.length
    rec: dict[str, Any] = {
        "cause": dg.cause_,
        "confidence": dg.confidence_,
        "baseline": _model_record(dg.baseline_, dg.baseline_nrmse_,
                                  dg.spectral_error_["baseline"], dg.energy_["baseline"],
                                  base_chi2),
        "extended": {**_model_record(dg.extended_, dg.extended_nrmse_,
                                     dg.spectral_error_["extended"], dg.energy_["extended"],
                                     final_chi2),
                     "cause": dg.cause_, "causes": [s.cause for s in dg.causes_]},
        "gain": dg.gain_,
        "candidates": [{"cause": c.cause, "gain": c.gain, "score": c.score,
                        **({} if math.isnan(c.decision_gain) else
                           {"decision_gain": c.decision_gain,
                            "decision_gain_basis": OWN_GAIN_BASIS}),
                        "evidence": c.evidence, "delta_chi2": c.delta_chi2,
                        "threshold": c.threshold, "significant": c.significant,
                        "heldout_nrmse": c.heldout_nrmse, "n_parameters": c.n_parameters,
                        "equation": c.model.equation(),
                        "details": {k: v for k, v in c.details.items() if k != "text"}}
                       for c in dg.candidates_],
        "causes": [{"cause": s.cause, "gain": s.gain, "evidence": s.evidence,
                    "delta_chi2": s.delta_chi2, "threshold": s.threshold,
                    "confidence": s.confidence,
                    "removal_chi2_rise": None if s.removal is None else s.removal.chi2_rise,
                    "removal_gain": None if s.removal is None else s.removal.gain,
                    "removal_note": None if s.removal is None else s.removal.note or None,
                    **({} if s.removal is None or math.isnan(s.removal.decision_gain) else
                       {"removal_decision_gain": s.removal.decision_gain,
                        "removal_decision_gain_basis": OWN_GAIN_BASIS}),
                    **({} if math.isnan(s.decision_gain) else
                       {"decision_gain": s.decision_gain})}
                   for s in dg.causes_],
        "not_separated": [_tie_record(s.cause, k, t) for k, s in enumerate(dg.causes_, 1)
                          for t in s.ties],
        "dropped_causes": [_removal_record(d) for d in dg.dropped_causes_],
        "figures": figures,
        "format": REPORT_FORMAT,
        "afmlearn_version": afmlearn.__version__,
        "input": str(Path(input_path).resolve()),
        "row": row,
        "explanation": (hyps[dg.cause_].explanation if dg.cause_ in hyps else
                        dg.untested_reason_ or _NONE_TEXT),
        "observations": [
            {"index": o.index, "kind": o.kind, "gap_m": o.gap_m,
             "baseline_heldout_nrmse": o.baseline_nrmse,
             "extended_heldout_nrmse": o.extended_nrmse,
             "drive_phase_rad": -o.extended.spec.drive_phase,
             "n_harmonics": o.orbit.n_h, "noise_rms_m": o.orbit.noise_rms * length}
            for o in dg.observations_],
        "heldout": {"design": dg.design_, "folds": dg.folds_,
                    "heldout_fraction": dg.heldout_fraction if dg.design_ == "tail" else None},
        "contact_exponent": (None if dg.exponent_interval_ is None else
                             {"exponent": dg.exponent_, "interval_95": dg.exponent_interval_,
                              "bounded": dg.exponent_bounded_}),
        "energy_per_cycle_j": {k: v * cal.scales.energy for k, v in dg.energy_.items()},
        "free_trace_harmonics": dg.free_harmonics_,
        "noise": {"rms_m": dg.orbit_.noise_rms * length, "n_harmonics": dg.orbit_.n_h},
        "split": {"heldout_start": dg.heldout_start_, "n_samples": cal.n_samples,
                  "heldout_fraction": dg.heldout_fraction},
        "calibration": {"spring_constant_n_per_m": cal.scales.spring_constant,
                        "resonance_frequency_hz": cal.scales.resonance_frequency,
                        "length_m": length, "quality_factor": cal.quality_factor,
                        "omega": cal.omega, "drive_amplitude": dg.orbit_.drive_amplitude,
                        "drive_source": cal.drive_source, "excitation": cal.excitation,
                        "excitation_assumed": cal.excitation_assumed,
                        "samples_per_period": cal.samples_per_period},
        "thresholds": {"per_cause": dg.calibration_.thresholds,
                       "min_gain": dg.calibration_.min_gain,
                       "source": dg.calibration_.source},
        "warnings": list(dg.warnings_),
        "runtime_s": runtime_s,
    }
    if qrnn is not None:
        rec["qrnn_coupling"] = qrnn
    return jsonable(rec)


def _tie_record(cause: str, step: int, t: Tie) -> dict[str, Any]:
    return {"cause": cause, "step": step, "not_separated_from": t.cause,
            "delta_chi2": t.named_delta_chi2, "other_delta_chi2": t.delta_chi2,
            "chi2_difference_sd": t.chi2_sd, "heldout_nrmse": t.named_heldout_nrmse,
            "other_heldout_nrmse": t.heldout_nrmse, "heldout_better_at": t.better_at,
            "heldout_set_points": t.n, "heldout_sign_p": t.p, "text": t.text(cause)}


def _removal_record(d: Removal) -> dict[str, Any]:
    return {"cause": d.cause, "chi2_rise": d.chi2_rise, "threshold": d.threshold,
            "heldout_gain": d.gain, "reason": d.reason,
            **({} if math.isnan(d.decision_gain) else
               {"decision_gain": d.decision_gain, "decision_gain_basis": OWN_GAIN_BASIS})}


def report_markdown(rec: dict[str, Any], figs: dict[str, Path]) -> str:
    """``report.md``: the verdict, the two equations, the candidates table, the figures."""
    cause = rec["cause"]
    b, e = rec["baseline"], rec["extended"]
    names = ([Path(p).name for p in rec["input"]] if isinstance(rec["input"], list)
             else [Path(rec["input"]).name])
    lines = [f"# Diagnosis of {' + '.join(f'`{n}`' for n in names)}", ""]
    if cause == "none":
        lines.append(f"**Cause: none** -- {rec['explanation']} (confidence "
                     f"{rec['confidence']:.2f}).")
    else:
        lines.append(f"**Cause: `{cause}`** -- {rec['explanation']}. Confidence "
                     f"{rec['confidence']:.2f}; the extended model cuts the held-out error by "
                     f"**{100 * rec['gain']:.1f} %** (NRMSE {b['heldout_nrmse']:.3g} -> "
                     f"{e['heldout_nrmse']:.3g}).")
    ties = rec.get("not_separated") or []
    if ties:
        # the data do not separate these candidates: said with the verdict, not hidden
        for t in ties:
            lines += ["", f"**Tie:** {t['text']}."]
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
    # a gain is measured only as far as the decision needs (n/c: not computed)
    for c in rec["candidates"]:
        # a gain measured on the cause's own signature decided: both shown
        gain = _num(c["gain"], "+.3f") + (f" (decided by {c['decision_gain']:+.3f}: "
                                          f"{c['decision_gain_basis']})"
                                          if "decision_gain" in c else "")
        lines.append(f"| {c['cause']} | {c['delta_chi2']:.1f} | {c['threshold']:.1f} | "
                     f"{gain} | {'yes' if c['significant'] else 'no'} | "
                     f"{c['evidence']} |")
    design = rec["heldout"]["design"]
    held = (f"the last {100 * rec['split']['heldout_fraction']:.0f} % of the periods, never "
            f"fitted" if design == "tail" else
            f"whole set-points, each predicted by the model refitted without it ({design}, "
            f"{len(rec['heldout']['folds'])} refits)")
    lines += ["", "Evidence: drop of the output-error chi-square (orbit harmonics in units of "
              "their noise) when the cause's extension is added; significant above the "
              "threshold calibrated on null data and with a held-out gain above "
              f"{rec['thresholds']['min_gain']:g}. Held-out: {held}.", ""]
    if len(rec["causes"]) > 1:
        lines += ["## Causes, step by step", "",
                  "Each tested against the model extended by the ones before it.", "",
                  "| step | cause | chi2 drop | threshold | gain added |", "|---|---|---|---|---|"]
        for k, c in enumerate(rec["causes"], 1):
            lines.append(f"| {k} | {c['cause']} | {c['delta_chi2']:.1f} | "
                         f"{c['threshold']:.1f} | {c['gain']:+.3f} |")
        lines.append("")
    dropped = rec.get("dropped_causes") or []
    if dropped:
        lines += ["## Dropped by the backward check", "",
                  "Named step by step, then removed from the final model (the rest refitted "
                  "without it): its removal did not raise chi2 above its threshold, or its "
                  "held-out gain in the final model was not above "
                  f"{rec['thresholds']['min_gain']:g}.", "",
                  "| cause | chi2 rise on removal | threshold | held-out gain | reason |",
                  "|---|---|---|---|---|"]
        for d in dropped:
            lines.append(f"| {d['cause']} | {d['chi2_rise']:.1f} | {d['threshold']:.1f} | "
                         f"{_num(d['heldout_gain'], '+.3f')} | {d['reason']} |")
        lines.append("")
    ce = rec.get("contact_exponent")
    if ce:
        # the exponent the equations use, never an unbounded free fit's edge value as if it
        # were measured (issue 14 audit)
        used = float(e.get("parameters", {}).get("contact_exponent", SPHERE_EXPONENT))
        lines += [f"Contact exponent {exponent_summary(ce, used=used)}.", ""]
    if len(rec["observations"]) > 1:
        lines += ["## Held-out NRMSE per set-point", "",
                  "| observation | rest gap [nm] | baseline | extended |", "|---|---|---|---|"]
        for o in rec["observations"]:
            lines.append(f"| {o['index']} ({o['kind']}) | {o['gap_m'] * 1e9:.2f} | "
                         f"{_num(o['baseline_heldout_nrmse'], '.4g')} | "
                         f"{_num(o['extended_heldout_nrmse'], '.4g')} |")
        lines.append("")
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


def _num(v: float | None, fmt: str) -> str:
    """``v`` formatted, ``n/c`` (not computed) for None / NaN."""
    return "n/c" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def _write_text(path: Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path
