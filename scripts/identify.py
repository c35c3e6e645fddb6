"""Identify the tip-sample force of a recorded trace (thin Hydra entry point).

Examples
--------
    python scripts/identify.py trace=outputs/trace.h5 out_dir=outputs/identify
    python scripts/identify.py trace=series.h5 out_dir=out          # all set-points jointly
    python scripts/identify.py trace=series.h5 row=3 out_dir=out    # one set-point alone
    python scripts/identify.py trace=sweep.h5 row=20 out_dir=out identifier=fast
    python scripts/identify.py 'trace=[a15.h5,a45.h5]' out_dir=out  # two files, one tip: jointly

Writes <out_dir>/result.json, model.json, force.h5 and figures (see
afmlearn.identify.infer.identify_trace; figures from afmlearn.plots.identify); the file's
/labels group is never read. Prints the equation and the contact exponent with its 95 %
profile-likelihood interval (saying so when the data do not bound it). Bad input (missing
calibration, fewer than 20 samples per drive period, clipped signal, NaN, not a trace file, a
sweep without `row`, files of different cantilevers) prints `error: ...` and exits with
status 2.

A list of files (e.g. set-point series of one tip at two free amplitudes: the second amplitude
is what bounds the contact exponent, docs/identify.md) is one experiment: every row of every
file is fitted jointly (afmlearn.identify.infer.read_files); result.json's `joint` lists the
inputs and each observation's (file, row).

A lock-in curve (an Asylum AM curve .ibw, or a trace with amplitude_m/phase_rad and no
deflection) gets the curve analysis instead (afmlearn.curves.analyze.identify_curve): the
baseline law fitted to the approach, <out_dir>/result.json with its equation and held-out
error on the retraction, and the curve figures; `+curves.max_nfev=...` etc. set the
CurveDiagnoser.
"""

from __future__ import annotations

import hydra
from _cli import bad_input_exits
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from afmlearn.curves import CurveDiagnoser
from afmlearn.curves.analyze import identify_curve, is_curve_file
from afmlearn.identify.infer import identify_trace
from afmlearn.identify.joint_outputs import format_exponent
from afmlearn.plots.curves import curve_figures
from afmlearn.plots.identify import identify_figures


@hydra.main(config_path="../conf", config_name="identify", version_base="1.3")
def main(cfg: DictConfig) -> None:
    """Run :func:`afmlearn.identify.infer.identify_trace` and print the equation."""
    paths = [str(p) for p in cfg.trace] if OmegaConf.is_list(cfg.trace) else [str(cfg.trace)]
    if len(paths) > 1 and any(is_curve_file(p) for p in paths):
        with bad_input_exits():
            raise ValueError("trace: lock-in curves are identified one file at a time here; "
                             "for one law over several curves use scripts/analyze_curves.py "
                             "joint=true")
    if len(paths) == 1 and is_curve_file(paths[0]):
        with bad_input_exits(ValueError, OSError):
            curves = cfg.get("curves")
            res = identify_curve(paths[0], cfg.out_dir, index=cfg.row or 0,
                                 diagnoser=CurveDiagnoser(**curves) if curves else None,
                                 figures=curve_figures if cfg.figures else None)
        print(res["equation"])
        print(f"held-out NRMSE (retraction)     {_shown(res['heldout_nrmse'])}")
        print(f"wrote {cfg.out_dir}/result.json")
        return
    with bad_input_exits(ValueError):  # InputError, TraceFormatError, bad settings
        identifier = instantiate(cfg.identifier)
        result = identify_trace(paths, cfg.out_dir, row=cfg.row, identifier=identifier,
                                figures=identify_figures if cfg.figures else None)
    summary = result["summary"]
    print(result["equation"])
    print(result["equation_si"])
    print(format_exponent(summary))
    for key in ("peak_repulsive_force_n", "dissipated_energy_per_cycle_j",
                "contact_time_s", "state_accuracy_heldout"):
        print(f"{key:<30}  {_shown(summary.get(key))}")
    for warning in result["warnings"]:
        print(f"warning: {warning}")
    print(f"wrote {result['files']['result']}")


def _shown(value: object) -> str:
    """A summary value for the terminal: numbers to 6 digits, per-observation lists element by
    element, a value the pipeline does not compute for this input (None) said so."""
    if value is None:
        return "n/a (not computed for this input)"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_shown(v) for v in value) + "]"
    return str(value)


if __name__ == "__main__":
    main()
