"""Diagnose an AM-AFM lock-in curve (amplitude and phase versus distance; thin Hydra entry).

Examples
--------
    python scripts/analyze_curves.py trace=outputs/curve.h5 out_dir=outputs/curves
    python scripts/analyze_curves.py trace=AZ_0052.ibw out_dir=out     # an Asylum file
    python scripts/analyze_curves.py trace=On_Surface/ out_dir=out     # every file of a folder
    python scripts/analyze_curves.py trace=asylum/ out_dir=out time_limit_s=120  # resumable
    python scripts/analyze_curves.py trace=asylum/ out_dir=out joint=true group_size=3

Writes <out_dir>/report.json (design.md section 3 keys plus `curve`: free amplitude, surface
position, dissipated energy, adhesion) and figures (afmlearn.plots.curves). The file's /labels
group is never read. A folder (searched recursively) runs each curve in a child process under
`time_limit_s` (a timeout or crash is listed, never stops the batch) and skips curves whose
report.json exists (`resume=false` redoes them); `transfer_sources=N` then predicts other
curves of the same group with N curves' fitted laws (transfer.json: gain on other curves).
`joint=true` (a folder) fits ONE law jointly to sets of `group_size` curves of each sub-folder
(one tip; the curves' k, f0 and Q must agree), each set spanning the free amplitudes, with the
gain measured on a curve left out of the fit: <out_dir>/<sub-folder>/set_<k>/report.json and
<out_dir>/joint_summary.json (the sets' agreement on the cause); `time_limit_s` is then per set.
Bad input prints `error: ...` (one line) and exits with status 2 (a folder: when no file
in it could be analysed).
"""

from __future__ import annotations

from pathlib import Path

import hydra
from _cli import bad_input_exits
from hydra.utils import instantiate
from omegaconf import DictConfig

from afmlearn.curves.analyze import analyze_curve, analyze_folder
from afmlearn.curves.analyze_group import analyze_folder_joint
from afmlearn.curves.transfer import transfer_gains
from afmlearn.io import write_json
from afmlearn.plots.curves import curve_figures, plot_parameter_spread
from afmlearn.plots.curves_group import group_figures


@hydra.main(config_path="../conf", config_name="analyze_curves", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.curves.analyze.analyze_curve` and print the finding."""
    figures = curve_figures if cfg.figures else None
    with bad_input_exits(ValueError, OSError):  # RecordingError, TraceFormatError: ValueErrors
        if cfg.joint:
            if not Path(cfg.trace).is_dir():
                raise ValueError(f"joint=true needs a folder of curves, got trace={cfg.trace}")
            joint = analyze_folder_joint(
                cfg.trace, cfg.out_dir, make_diagnoser=lambda: instantiate(cfg.group_diagnoser),
                group_size=cfg.group_size, max_sets=cfg.max_sets,
                figures=group_figures if cfg.figures else None,
                time_limit_s=cfg.time_limit_s, resume=cfg.resume)
            for g, gs in joint["groups"].items():
                print(f"  {g}: {gs['majority']} on {gs['agreement']:.0%} of {gs['n_sets']} "
                      f"sets of {cfg.group_size} (causes {gs['causes']}), median gain "
                      f"{gs['median_gain']:.3f}, {gs['errors']} errors")
            print(f"wrote {cfg.out_dir}/joint_summary.json")
            return
        if Path(cfg.trace).is_dir():
            summary = analyze_folder(cfg.trace, cfg.out_dir,
                                     make_diagnoser=lambda: instantiate(cfg.diagnoser),
                                     figures=figures,
                                     summary_figure=plot_parameter_spread if cfg.figures
                                     else None, time_limit_s=cfg.time_limit_s,
                                     resume=cfg.resume)
            if summary["n_analysed"] == 0:  # every file damaged: bad input, as for one file
                first = str(summary["curves"][0].get("error", "?")).splitlines()[0]
                raise ValueError(f"trace: none of the {summary['n_files']} curve files in "
                                 f"{cfg.trace} could be analysed (first: {first}); "
                                 f"{cfg.out_dir}/summary.json lists them")
            print(f"causes: {summary['causes']} ({summary['n_analysed']} of "
                  f"{summary['n_files']} files)")
            for g, gs in summary["groups"].items():
                print(f"  {g}: {gs['majority']} on {gs['agreement']:.0%}, positive gain on "
                      f"{gs['gain_positive']:.0%} of {gs['n_named']} named (median "
                      f"{gs['median_gain']:.3f}), {gs['errors']} errors")
            if cfg.transfer_sources > 0:
                tr = transfer_gains(summary, cfg.trace, n_sources=cfg.transfer_sources,
                                    n_targets=cfg.transfer_targets,
                                    step=float(cfg.diagnoser.step))
                write_json(Path(cfg.out_dir) / "transfer.json", tr)
                print(f"other curves: median gain {tr['median_gain']:.3f}, positive on "
                      f"{tr['gain_positive']:.0%} of {len(tr['pairs'])} pairs")
            print(f"wrote {cfg.out_dir}/summary.json")
            return
        diagnoser = instantiate(cfg.diagnoser)
        report = analyze_curve(cfg.trace, cfg.out_dir, diagnoser=diagnoser, index=cfg.index,
                               figures=figures)
    print(f"cause: {report['cause']} (confidence {report['confidence']:.2f}, held-out gain "
          f"{report['gain']:.3f})")
    print(f"baseline: {report['baseline']['equation']}")
    print(f"extended: {report['extended']['equation']}")
    print(f"wrote {cfg.out_dir}/report.json")


if __name__ == "__main__":
    main()
