"""Mode-coupling flag, sweet spot and orbit forecast on a recorded trace (format v1).

:func:`infer` is the function behind ``scripts/infer_qrnn.py trace=PATH out_dir=DIR``. It reads
the file with :func:`afmlearn.io.read_trace` (``labels=False``: the ``/labels`` group of a
simulated file is never opened), cuts it into windows exactly like the training data
(:func:`afmlearn.qrnn.data.windows_from_trace`: one drive period in, ``horizon`` periods to
predict, normalised by the input period) and runs the trained
:class:`~afmlearn.qrnn.module.OrbitModule`. It writes, atomically:

``coupling.json``
    ``score`` (mean window coupling score) and ``flag`` (``score >= threshold``) for every trace
    (sweep row), with its drive frequency, sweet-spot score and the NRMSE of the orbit forecast
    against the measured following periods; for sweeps, the sweet-spot interval of each sweep
    direction in Hz (or null); the checkpoint used; the model's settings.
figures (``figures=`` a figure maker, e.g. :func:`afmlearn.plots.qrnn.inference_figures`)
    ``prediction.png`` (predicted vs measured deflection and orbit of one window: the trace, or
    the sweep row with the highest coupling score) and, for sweeps, ``scores.png`` (coupling and
    sweet-spot score vs drive frequency with the interval shaded).

Bad input raises ``ValueError`` (files breaking the format: ``TraceFormatError``, a
``ValueError``) with a message naming the problem. The checks are those of ``identify`` and
``diagnose`` (:func:`afmlearn.preprocess.checks.check_trace`: clipped / saturated signal, NaN /
inf samples, fewer than 20 samples per drive period, a non-positive rest gap) plus a row shorter
than one input period plus the horizon and a missing file.

The shipped checkpoint :data:`DEFAULT_CHECKPOINT` is used unless ``checkpoint`` is given; any
checkpoint written by :func:`afmlearn.qrnn.train.train` (``last.ckpt``, the best one, or an
``export``) works.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra.utils import instantiate

from afmlearn.io import Trace, read_trace, write_json
from afmlearn.preprocess.checks import check_trace
from afmlearn.qrnn.calibration import CouplingCalibration
from afmlearn.qrnn.coupling import directions, sweet_spot_interval, trace_scores
from afmlearn.qrnn.data import windows_from_trace
from afmlearn.qrnn.evaluate import nrmse_per_period
from afmlearn.qrnn.module import CHECKPOINT_KEY, OrbitModule

__all__ = ["DEFAULT_CHECKPOINT", "FigureMaker", "calibration_of", "load_module",
           "predict_trace", "infer", "coupling_summary"]

#: checkpoint shipped with the package (trained by ``experiment=qrnn_default``)
DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "checkpoints" / "qrnn_default.ckpt"

#: draws the figures of one inference into a folder and returns their paths:
#: ``maker(result, out_dir, run)`` with ``result`` the output of :func:`predict_trace` and
#: ``run`` the checkpoint's run settings (the plots layer provides one; analyses never draw)
FigureMaker = Callable[[dict[str, Any], Path, dict[str, Any]], list[str]]

#: module arguments of the model config that inference does not need
_NOT_FOR_INFERENCE = ("name", "net", "optimizer", "scheduler")


def load_module(checkpoint: str | os.PathLike[str] | None = None
                ) -> tuple[OrbitModule, dict[str, Any], Path]:
    """Rebuild the trained module of a checkpoint (evaluation mode, CPU).

    Parameters
    ----------
    checkpoint : path, optional
        A checkpoint of :func:`afmlearn.qrnn.train.train`; default :data:`DEFAULT_CHECKPOINT`.

    Returns
    -------
    module : OrbitModule
    run : dict
        ``config`` (resolved training configuration), ``input_size``, ``samples_per_period``,
        ``horizon`` (and ``metrics`` for exported checkpoints).
    path : Path
        The checkpoint file used.
    """
    path = Path(checkpoint) if checkpoint is not None else DEFAULT_CHECKPOINT
    if not path.is_file():
        hint = (" (the shipped checkpoint is missing: train one with `python scripts/"
                "train_qrnn.py experiment=qrnn_default` or pass checkpoint=PATH)"
                if checkpoint is None else "")
        raise ValueError(f"checkpoint: no such file {str(path)!r}{hint}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - any unpickling failure means "not ours"
        raise ValueError(f"checkpoint: {str(path)!r} is not a readable torch checkpoint "
                         f"({type(err).__name__}: {err})") from err
    meta = ckpt.get(CHECKPOINT_KEY) if isinstance(ckpt, dict) else None
    if not meta or not meta.get("run") or "state_dict" not in ckpt:
        raise ValueError(f"checkpoint: {str(path)!r} holds no afmlearn QRNN model (written by "
                         "afmlearn.qrnn.train.train?)")
    run = dict(meta["run"])
    if "metrics" in meta:
        run["metrics"] = meta["metrics"]
    if meta.get("calibration"):
        run["calibration"] = meta["calibration"]
    if meta.get("calibration_by_kind"):
        run["calibration_by_kind"] = meta["calibration_by_kind"]
    model_cfg = run["config"]["model"]
    net = instantiate(model_cfg["net"], input_size=int(run["input_size"]))
    module = instantiate({k: v for k, v in model_cfg.items() if k not in _NOT_FOR_INFERENCE},
                         net=net)
    module.load_state_dict(ckpt["state_dict"])
    module.run_config = meta["run"]
    module.eval()
    return module, run, path


def _direction_name(omega: np.ndarray) -> str:
    if omega.size < 2 or omega[-1] == omega[0]:
        return "single"
    return "forward" if omega[-1] > omega[0] else "reverse"


def calibration_of(run: dict[str, Any], kind: str | None = None
                   ) -> CouplingCalibration | None:
    """The checkpoint's coupling calibration (None for an uncalibrated checkpoint).

    ``kind`` = ``"steady"`` (single records, set-points) or ``"sweep"`` (sweep points) picks
    that kind's own calibration and threshold when the checkpoint has one; None (or a kind
    without one) gives the calibration fitted on all traces.
    """
    data = (run.get("calibration_by_kind") or {}).get(kind) if kind else None
    data = data or run.get("calibration")
    return CouplingCalibration.from_dict(data) if data else None


def training_band(run: dict[str, Any]) -> tuple[float, float]:
    """Drive frequencies ``(lo, hi)`` / f0 the checkpoint was trained on (sweeps and set-point
    series of its data spec; DatasetSpec defaults where the spec leaves them out)."""
    from afmlearn.qrnn.datagen import DatasetSpec

    spec = dict((run.get("config") or {}).get("data", {}).get("spec") or {})
    d = DatasetSpec()
    series = spec.get("series_omega_range", d.series_omega_range)
    return (float(min(spec.get("omega_start", d.omega_start), series[0])),
            float(max(spec.get("omega_stop", d.omega_stop), series[1])))


def predict_trace(trace: Trace | str | os.PathLike[str], module: OrbitModule,
                  run: dict[str, Any], *, threshold: float | None = None) -> dict[str, Any]:
    """Scores, flags, sweet-spot intervals and forecasts of one trace, sweep or set-point
    series (no files).

    Parameters
    ----------
    trace : Trace or path
        A recording (read without labels when a path).
    module, run : OrbitModule, dict
        From :func:`load_module`.
    threshold : float, optional
        Flag threshold in (0, 1) on the trace score. Default: the checkpoint's calibrated
        threshold (chosen for its stated false-flag rate; the one of the record kind --
        sweep points or steady records -- when the checkpoint has one), or 0.5 uncalibrated.

    Returns
    -------
    dict
        ``summary`` (JSON-ready, the body of ``coupling.json``) and ``arrays``
        (``windows`` of :func:`windows_from_trace`, ``pred`` (N, horizon P) normalised forecast,
        ``coupled``, ``sweet`` (N,) window scores). A trace's ``score`` is the calibrated
        probability of coupling when the checkpoint is calibrated (``raw_score``: the mean
        window score); the sweet-spot interval uses the raw sweet score at 0.5. A trace driven
        outside the checkpoint's training band (:func:`training_band`) is scored but never
        flagged (``in_band`` False): e.g. the dissertation's sweet-spot sweep up to 1.13 f0 got
        76 false flags of 251 uncoupled points at 1.03-1.13 f0 with the sweep threshold, none
        inside the band.
    """
    if not isinstance(trace, Trace):
        trace = read_trace(trace)          # labels=False: /labels is never opened
    cal = calibration_of(run, "sweep" if trace.is_sweep else "steady")
    if threshold is None:
        threshold = cal.threshold if cal is not None else 0.5
    elif not 0.0 < float(threshold) < 1.0:
        raise ValueError(f"threshold must be in (0, 1), got {threshold!r}")
    if trace.deflection_m is None:
        raise ValueError("deflection_m: the trace holds lock-in curves (amplitude/phase) only; "
                         "the QRNN needs the deflection record")
    # the same refusals as identify / diagnose: clipped (saturated) signal, NaN/inf, too few
    # samples per drive period, non-positive rest gap (afmlearn.preprocess.checks)
    check_trace(trace)
    p, horizon = int(run["samples_per_period"]), int(run["horizon"])
    win = windows_from_trace(trace, samples_per_period=p, horizon=horizon)
    out = module.predict_windows(torch.from_numpy(np.ascontiguousarray(win["x"])))
    pred = out["y"].numpy().astype(float)
    coupled, sweet = out["coupled"].numpy(), out["sweet"].numpy()
    rows, raw = trace_scores(coupled, win["row"])
    score = cal.probability(raw) if cal is not None else raw
    _, sweet_score = trace_scores(sweet, win["row"])
    err = nrmse_per_period(pred, win["y"].astype(float), horizon=horizon)
    f0 = trace.resonance_frequency_hz
    f_rows = np.asarray(win["omega_rows"], dtype=float) * f0
    lo, hi = training_band(run)
    traces = []
    for i, r in enumerate(rows):
        sel = win["row"] == r
        in_band = bool(lo - 1e-9 <= float(win["omega_rows"][r]) <= hi + 1e-9)
        traces.append({
            "row": int(r), "drive_frequency_hz": float(f_rows[r]),
            "omega": float(win["omega_rows"][r]), "score": float(score[i]),
            "raw_score": float(raw[i]),
            "flag": bool(score[i] >= threshold and in_band), "in_band": in_band,
            "sweet_score": float(sweet_score[i]),
            "n_windows": int(sel.sum()),
            "forecast_nrmse_per_period": [float(v) for v in err[sel].mean(axis=0)],
        })
        if trace.is_series:
            traces[-1]["gap_m"] = float(np.asarray(trace.gap_m)[r])
    summary: dict[str, Any] = {
        "is_sweep": bool(trace.is_sweep), "is_series": bool(trace.is_series),
        "n_traces": len(traces), "threshold": float(threshold),
        "drive_band": [lo, hi], "n_out_of_band": sum(not t["in_band"] for t in traces),
        "calibrated": cal is not None,
        "false_flag_rate": None if cal is None else cal.false_flag_rate,
        "traces": traces,
    }
    if trace.is_sweep:
        summary["flagged_fraction"] = float(np.mean([t["flag"] for t in traces]))
        spots = []
        for part in directions(f_rows[rows]):
            f, s = f_rows[rows][part], sweet_score[part]
            iv = sweet_spot_interval(f, s, threshold=0.5)
            spots.append({"direction": _direction_name(f), "rows": [int(rows[part][0]),
                                                                    int(rows[part][-1])],
                          "interval_hz": None if iv is None else [iv[0], iv[1]]})
        summary["sweet_spot"] = spots
    elif trace.is_series:
        summary["flagged_fraction"] = float(np.mean([t["flag"] for t in traces]))
        summary["score"] = float(np.max(score))
        summary["flag"] = any(t["flag"] for t in traces)
        summary["sweet_spot"] = None
    else:
        summary["score"] = traces[0]["score"]
        summary["flag"] = traces[0]["flag"]
        summary["sweet_spot"] = None
    return {"summary": summary,
            "arrays": {"windows": win, "pred": pred, "coupled": coupled, "sweet": sweet,
                       "rows": rows, "score": score, "sweet_score": sweet_score,
                       "frequency_hz": f_rows[rows]}}


def infer(trace_path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
          checkpoint: str | os.PathLike[str] | None = None, threshold: float | None = None,
          figures: FigureMaker | None = None) -> dict[str, Any]:
    """Run the model on a trace file and write ``coupling.json`` (+ figures) into ``out_dir``.

    Parameters
    ----------
    trace_path : path
        Trace-format-v1 file (one trace or a sweep).
    out_dir : path
        Output folder (created).
    checkpoint : path, optional
        Default: the shipped :data:`DEFAULT_CHECKPOINT`.
    threshold : float, optional
        Flag threshold in (0, 1); default: the checkpoint's calibrated threshold (0.5 when
        uncalibrated).
    figures : FigureMaker, optional
        Also draw the PNG figures with it (``scripts/infer_qrnn.py`` passes
        :func:`afmlearn.plots.qrnn.inference_figures`); None: no figures.

    Returns
    -------
    dict
        The content of ``coupling.json`` plus ``"output"``: its path.
    """
    trace_path = Path(trace_path)
    trace = read_trace(trace_path)         # labels=False
    module, run, used = load_module(checkpoint)
    result = predict_trace(trace, module, run, threshold=threshold)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = {"trace": str(trace_path.resolve()), "checkpoint": str(used.resolve()),
               "model": {"network": type(module.net).__name__,
                         "forecast": type(module.forecast).__name__,
                         "hidden_size": int(module.net.hidden_size),
                         "samples_per_period": int(run["samples_per_period"]),
                         "horizon": int(run["horizon"])},
               **result["summary"]}
    summary["figures"] = list(figures(result, out, run)) if figures is not None else []
    write_json(out / "coupling.json", summary)
    return {**summary, "output": str(out / "coupling.json")}


def coupling_summary(trace: Trace | str | os.PathLike[str], *,
                     checkpoint: str | os.PathLike[str] | None = None,
                     threshold: float | None = None) -> str:
    """A few lines for a terminal: coupling score / flag and the sweet spot of a trace or sweep.

    Uses the shipped checkpoint unless ``checkpoint`` is given; writes nothing.
    """
    module, run, used = load_module(checkpoint)
    s = predict_trace(trace, module, run, threshold=threshold)["summary"]
    threshold = s["threshold"]
    name = "shipped checkpoint" if checkpoint is None else used.name
    head = f"QRNN mode-coupling ({type(module.net).__name__}, {name}):"
    what = "probability" if s["calibrated"] else "score"
    rule = (f"threshold {threshold:.3g}" + (f" for {s['false_flag_rate']:.0%} false flags"
                                           if s["calibrated"] else ""))
    lo, hi = s["drive_band"]
    band = (f"; {s['n_out_of_band']} driven outside the training band {lo:.3f}-{hi:.3f} f0: "
            "scored, never flagged" if s["n_out_of_band"] else "")
    if not s["is_sweep"] and not s["is_series"]:
        t = s["traces"][0]
        return (f"{head} {what} {t['score']:.3f} -> "
                f"{'coupled' if t['flag'] else 'not coupled'} ({rule}{band}), "
                f"drive {t['drive_frequency_hz'] / 1e3:.3f} kHz")
    if s["is_series"]:
        lines = [head]
        for t in s["traces"]:
            lines.append(f"  set-point gap {t['gap_m'] * 1e9:.2f} nm: {what} {t['score']:.3f} -> "
                         f"{'coupled' if t['flag'] else 'not coupled'}")
        lines.append(f"  ({rule}{band})")
        return "\n".join(lines)
    lines = [head]
    scores = np.array([t["score"] for t in s["traces"]])
    k = int(np.argmax(scores))
    n_flagged = sum(t["flag"] for t in s["traces"])
    lines.append(f"  {s['n_traces']} sweep points, {n_flagged} flagged coupled "
                 f"({what} >= {threshold:.3g}{band}); max {what} {scores[k]:.3f} at "
                 f"{s['traces'][k]['drive_frequency_hz'] / 1e3:.3f} kHz")
    for spot in s["sweet_spot"]:
        iv = spot["interval_hz"]
        where = ("none" if iv is None
                 else f"{iv[0] / 1e3:.3f} - {iv[1] / 1e3:.3f} kHz")
        lines.append(f"  sweet spot ({spot['direction']}): {where}")
    return "\n".join(lines)
