"""Diagnose a recording: what the baseline gets wrong, the causes, the gain (Hydra entry).

Examples
--------
    python scripts/diagnose.py trace=outputs/demo/measured.h5 out_dir=outputs/diagnose
    python scripts/diagnose.py trace=series.h5 out_dir=out diagnoser.max_folds=8
    python scripts/diagnose.py trace=sweep.h5 row=40 out_dir=out diagnoser.progress=true
    python scripts/diagnose.py "trace=[amp1.h5,amp2.h5]" out_dir=out

A set-point series is diagnosed as one experiment (every row, one force law; held-out =
whole set-points), a ramp through quasi-steady windows, one steady record with its last
periods held out. A list of files of one tip (e.g. set-point series at two free amplitudes,
which bound the contact law where one amplitude cannot) is one experiment: every row of
every file, one force law, one drive amplitude per free amplitude (docs/diagnose.md,
"Several free amplitudes"); files of another cantilever exit 2.
Writes <out_dir>/report.json (design.md section 3), report.md and the figures
(afmlearn.plots.diagnose.plot_all, drawn here: the analysis never imports the plots); the
file's /labels group is never read. Bad input (missing calibration, fewer than 20
samples per drive period, clipped signal, NaN, not a trace file, a sweep without `row`)
prints `error: ...` and exits with status 2.

A lock-in curve (an Asylum AM curve .ibw, or a trace with amplitude_m/phase_rad and no
deflection) gets the curve diagnosis instead (afmlearn.curves.analyze.analyze_curve, as
scripts/analyze_curves.py): <out_dir>/report.json and the curve figures;
`+curves.max_nfev=...` etc. set the CurveDiagnoser.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from hydra.utils import instantiate
from omegaconf import DictConfig, ListConfig

from afmlearn.curves import CurveDiagnoser
from afmlearn.curves.analyze import analyze_curve, is_curve_file
from afmlearn.diagnose.hypotheses.contact_geometry import exponent_summary
from afmlearn.diagnose.report import diagnose_trace
from afmlearn.plots.curves import curve_figures
from afmlearn.plots.diagnose import plot_all


def _paths(trace: object) -> str | list[str]:
    """``trace=``: one path, or a list of paths (files of one tip: one experiment)."""
    if isinstance(trace, (ListConfig, list, tuple)):
        paths = [str(p) for p in trace]
        if not paths:
            raise ValueError("trace must name a trace file or a non-empty list of them, "
                             "got []")
        if any(is_curve_file(p) for p in paths):
            raise ValueError("trace: lock-in curves are diagnosed one file at a time "
                             "(scripts/analyze_curves.py for a folder of curves)")
        return paths[0] if len(paths) == 1 else paths
    return str(trace)


@hydra.main(config_path="../conf", config_name="diagnose", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.diagnose.report.diagnose_trace` and print the verdict."""
    with bad_input_exits(ValueError):
        trace = _paths(cfg.trace)
    if isinstance(trace, str) and is_curve_file(trace):
        with bad_input_exits(ValueError, OSError):
            curves = cfg.get("curves")
            rep = analyze_curve(trace, cfg.out_dir, index=cfg.row or 0,
                                diagnoser=CurveDiagnoser(**curves) if curves else None,
                                figures=curve_figures if cfg.figures else None)
        print(f"cause        {rep['cause']}  (confidence {_num(rep['confidence'], '.2f')})")
        print(f"gain         {_num(rep['gain'], '.3f')}  (held-out NRMSE, retraction "
              f"{_num(rep['baseline']['heldout_nrmse'], '.4g')} -> "
              f"{_num(rep['extended']['heldout_nrmse'], '.4g')})")
        print(f"baseline     {rep['baseline']['equation']}")
        print(f"extended     {rep['extended']['equation']}")
        print(f"report       {cfg.out_dir}/report.json")
        return
    with bad_input_exits(ValueError):  # InputError, TraceFormatError, bad settings
        diagnoser = instantiate(cfg.diagnoser)
        rep = diagnose_trace(trace, cfg.out_dir, row=cfg.row, diagnoser=diagnoser,
                             figures=plot_all if cfg.figures else None)
    print(f"cause        {rep['cause']}  (confidence {_num(rep['confidence'], '.2f')})")
    if len(rep["causes"]) > 1:
        print("causes       " + ", then ".join(f"{c['cause']} (gain {_num(c['gain'], '+.3f')})"
                                              for c in rep["causes"]))
    print(f"gain         {_num(rep['gain'], '.3f')}  (held-out NRMSE "
          f"{_num(rep['baseline']['heldout_nrmse'], '.4g')} -> "
          f"{_num(rep['extended']['heldout_nrmse'], '.4g')})")
    print(f"baseline     {rep['baseline']['equation']}")
    print(f"extended     {rep['extended']['equation']}")
    if rep["contact_exponent"]:
        used = rep["extended"]["parameters"]["contact_exponent"]
        print(f"exponent     {exponent_summary(rep['contact_exponent'], used=used)}")
    for warning in rep["warnings"]:
        print(f"warning: {warning}")
    print(f"report       {cfg.out_dir}/report.md")


def _num(value: object, fmt: str) -> str:
    """A report number for the terminal; one the record does not hold (None: not computed,
    or NaN/inf turned into null by the JSON record) is said so, not printed as ``None``."""
    if value is None:
        return "n/a (not computed)"
    return format(value, fmt)


if __name__ == "__main__":
    main()
