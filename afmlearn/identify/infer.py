"""Identify the tip--sample force of one recorded trace file (or several) and write the results.

:func:`identify_trace` is the one function behind ``scripts/identify.py``. It reads a trace
format v1 file (or several files of one cantilever: :func:`read_files`, one experiment)
**without its /labels group** (``afmlearn.io.read_trace(path)``; the file name is
never interpreted), fits a :class:`ForceIdentifier` and writes into ``out_dir`` (each file
atomically: temporary sibling + ``os.replace``):

``result.json``
    The equation to quote (dimensionless and SI; when the data do not bound the contact
    exponent, the law re-fitted at the sphere's 1.5 and ``exponent_fixed`` says so, while
    ``fitted_equation`` is the fitted law of model.json: :mod:`.fixed_exponent`), the SI
    terms, the coefficients with their bagging bands, the physical summary (interaction
    exponent, dissipated energy per cycle, peak repulsive force, contact time, held-out state
    accuracy, ...), warnings, the calibration used, the candidates table with the knee and
    AICc choices, runtime, afmlearn version and the input path.
``model.json``
    The chosen :class:`IdentifiedModel` (``IdentifiedModel.load`` reloads it).
``force.h5``
    ``force_n`` [N] aligned sample by sample with the input deflection (same shape; NaN where
    the force is undefined and, for a sweep, in every row but the identified one),
    ``force_lo_n`` / ``force_hi_n`` (95 % band: bagging for one orbit, the output-error
    profile-likelihood band for a joint fit, :mod:`.force_band`; attribute ``band``),
    ``gap_m`` (instantaneous tip--sample gap of the denoised orbit, same shape) and ``time_s``
    (n,); units in attributes. When the exponent is fixed (``exponent_fixed`` attribute) the
    force and band are the quoted law's and ``fitted_force_n`` is the fitted law's.
Figures are the caller's (``figures``: a callable, e.g.
:func:`afmlearn.plots.identify.identify_figures` from ``scripts/identify.py``): this module never
imports :mod:`afmlearn.plots`.

Set-point series (a 2-D ``deflection_m`` with one rest gap per row): ALL rows are identified
jointly (one force law; :mod:`afmlearn.identify.joint`) unless ``row`` picks one.
Sweeps: one row is identified; ``row`` is then required (a ValueError lists the valid range).
The row cannot be chosen from the data without identifying every row, and picking one silently
would hide which drive frequency the result belongs to.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

import afmlearn
from afmlearn.io import Experiment, Trace, jsonable, read_trace, write_json
from afmlearn.io._atomic import atomic_path
from afmlearn.preprocess import Calibrated, calibrate, check_trace, checked_row

from .fixed_exponent import fixed_exponent_law
from .identifier import LINEAR_TERMS, ForceIdentifier
from .library import AFMLibrary

__all__ = ["identify_trace", "identify_and_describe", "read_files", "candidates_table",
           "calibration_record", "write_force_h5", "write_series_force_h5", "write_json",
           "jsonable", "RESULT_FORMAT"]

RESULT_FORMAT = "afmlearn-identify-result"
PathLike = str | os.PathLike[str]


#: ``figures(identifier, calibrated, out_dir) -> {name: path}`` (the script layer's plots)
FigureWriter = Callable[[ForceIdentifier, Calibrated, Path], dict[str, str]]


def identify_trace(path: PathLike | Sequence[PathLike], out_dir: str | os.PathLike[str], *,
                   row: int | None = None, identifier: ForceIdentifier | None = None,
                   figures: FigureWriter | None | bool = None) -> dict[str, Any]:
    """Identify the force of one trace file (one row of a sweep) and write the results.

    Parameters
    ----------
    path : str or os.PathLike, or a sequence of them
        Trace file, format v1. Its ``/labels`` group is never read. Several files (e.g. set-point
        series of one tip at two free amplitudes) are ONE experiment: every observation of
        every file is fitted jointly (:func:`read_files`); a sequence of one is one path.
    out_dir : str or os.PathLike
        Output folder (created if missing); existing result files are replaced.
    row : int, optional
        Row of a sweep, in ``[0, n_points)``; required for sweeps. For a set-point series
        None (default) identifies all rows jointly and ``row=i`` row ``i`` alone; must be None
        for a single trace.
    identifier : ForceIdentifier, optional
        Settings (unfitted; it is cloned by reference, i.e. fitted in place); default
        ``ForceIdentifier()``.
    figures : callable, optional
        ``figures(identifier, calibrated, out_dir)`` writes figures and returns their paths
        (None or False: no figures).

    Returns
    -------
    dict
        The content of ``result.json`` plus ``files`` (paths written) and, under the key
        ``identifier``, the fitted :class:`ForceIdentifier` (not serialised).

    Raises
    ------
    afmlearn.io.TraceFormatError
        Missing file, not HDF5, missing calibration attributes (a ValueError).
    afmlearn.preprocess.InputError
        NaN / inf, fewer than 20 samples per drive period, too short, clipped signal, bad
        calibration (a ValueError).
    ValueError
        ``row`` missing for a sweep or out of range, or bad identifier settings.
    """
    t0 = time.perf_counter()
    paths = _paths(path)
    out = Path(out_dir)
    ide = identifier if identifier is not None else ForceIdentifier()
    if not isinstance(ide, ForceIdentifier):
        raise ValueError(f"identifier must be a ForceIdentifier, got {type(ide).__name__}")
    if len(paths) > 1:
        if row is not None:
            raise ValueError(f"row must be null when several trace files are identified "
                             f"jointly, got {row!r}")
        return _identify_files(paths, out, ide, figures=figures, t0=t0)
    path = paths[0]
    trace = read_trace(path)                      # labels=False: /labels is never opened
    if getattr(trace, "is_series", False):
        if row is None:
            return _identify_series(trace, out, ide, input_path=path, figures=figures,
                                    t0=t0)
        if isinstance(row, bool) or not isinstance(row, int | np.integer) \
                or not 0 <= int(row) < trace.n_points:
            raise ValueError(f"row must be null (all rows jointly) or an integer in "
                             f"[0, {trace.n_points}) for a set-point series, got {row!r}")
        row = int(row)
        single = trace.row(row)
        check_trace(single)
        cal = calibrate(single)
    else:
        row = checked_row(trace, row)
        check_trace(trace, row=row)
        cal = calibrate(trace, row=row)
    ide.fit(cal)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    files["model"] = str(ide.model_.save(out / "model.json"))
    files["force"] = str(write_force_h5(out / "force.h5", ide, cal, trace, row=row))
    if figures:
        files.update(figures(ide, cal, out))
    result = result_record(ide, cal, input_path=path, row=row,
                           runtime_s=time.perf_counter() - t0)
    result["files"] = {**files, "result": str(out / "result.json")}
    write_json(out / "result.json", result)
    return {**result, "identifier": ide}


def identify_and_describe(path: PathLike | Sequence[PathLike],
                          out_dir: str | os.PathLike[str], *,
                          row: int | None = None,
                          identifier: ForceIdentifier | None = None) -> str:
    """Identify a trace or set-point series file (or several) and return the lines to show.

    :func:`identify_trace` (a series, several files: every row jointly), then the equation
    (dimensionless
    and SI) and the contact exponent with its 95 % profile-likelihood interval, saying so
    when the data do not bound it. The demo prints the returned text.
    """
    from .joint_outputs import format_exponent

    res = identify_trace(path, out_dir, row=row, identifier=identifier)
    n = res.get("joint", {}).get("n_observations", 1)
    n_files = len(res.get("joint", {}).get("inputs", ()))
    head = (f"joint fit of {n} set-points" + (f" from {n_files} files" if n_files > 1 else "")
            + " (one force law)" if n > 1 else "single-orbit fit")
    return "\n".join([head, res["equation"], res["equation_si"],
                      format_exponent(res["summary"])])


def _identify_series(trace: Trace, out: Path, ide: ForceIdentifier, *,
                     input_path: str | os.PathLike[str], figures: FigureWriter | None | bool,
                     t0: float) -> dict[str, Any]:
    """All rows of a set-point series jointly: fit, then write the same files."""
    exp = Experiment.from_trace(trace)
    ide.fit(exp)
    cal = ide.joint_.problem.observations[0].calibrated
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {"model": str(ide.model_.save(out / "model.json"))}
    files["force"] = str(write_series_force_h5(out / "force.h5", ide, trace))
    if figures:
        files.update(figures(ide, cal, out))
    result = result_record(ide, cal, input_path=input_path, row=None,
                           runtime_s=time.perf_counter() - t0)
    result["joint"] = {"n_observations": len(exp),
                       "rest_gaps_m": np.asarray(exp.gaps_m, float).tolist(),
                       "length_unit_m": ide.joint_.problem.length_m,
                       "offsets": ide.joint_.problem.offsets.tolist(),
                       "phase": jsonable(ide.joint_.phase_info)}
    result["files"] = {**files, "result": str(out / "result.json")}
    write_json(out / "result.json", result)
    return {**result, "identifier": ide}


def read_files(paths: Sequence[PathLike]) -> tuple[Experiment, list[tuple[int, int]]]:
    """The observations of several trace files as ONE experiment (one cantilever and tip).

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        Trace files (format v1: single steady traces or set-point series) or instrument files
        that hold steady records; read without their ``/labels`` group.

    Returns
    -------
    experiment : Experiment
        Every observation of every file, in the order given.
    origin : list of (int, int)
        ``(file index, row in that file)`` of each observation.

    Raises
    ------
    ValueError
        A file that cannot be read (TraceFormatError), a sweep, ramp or lock-in curve among
        them, files of different cantilevers (``Experiment``'s shared fields; the message names
        both files and the field), or records of different lengths.
    """
    obs: list[Trace] = []
    origin: list[tuple[int, int]] = []
    for k, p in enumerate(paths):
        exp = Experiment.read(p)                  # labels=False: /labels is never opened
        if exp.kind not in ("single", "series"):
            raise ValueError(f"trace: {Path(p).name} is a {exp.kind}; only steady traces and "
                             "set-point series can be identified jointly from several files")
        if obs:
            try:
                Experiment([obs[0], exp[0]])
            except ValueError as err:             # it names observations: say which files
                raise ValueError(f"trace: {Path(paths[0]).name} and {Path(p).name} are not of "
                                 f"one cantilever (identify them separately): {err}") from None
        for i, tr in enumerate(exp):
            if obs and tr.n_samples != obs[0].n_samples:
                raise ValueError(
                    f"trace: every record must have the same number of samples; "
                    f"{Path(paths[0]).name} has {obs[0].n_samples}, "
                    f"{Path(p).name} row {i} has {tr.n_samples}")
            obs.append(tr)
            origin.append((k, i))
    return Experiment(obs), origin


def _paths(path: PathLike | Sequence[PathLike]) -> list[Path]:
    if isinstance(path, str | os.PathLike):
        return [Path(path)]
    paths = [Path(p) for p in path]
    if not paths:
        raise ValueError("trace must name at least one file, got an empty list")
    return paths


def _identify_files(paths: list[Path], out: Path, ide: ForceIdentifier, *,
                    figures: FigureWriter | None | bool, t0: float) -> dict[str, Any]:
    """Every observation of several files jointly: fit, then write the same files."""
    exp, origin = read_files(paths)
    ide.fit(exp)
    cal = ide.joint_.problem.observations[0].calibrated
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {"model": str(ide.model_.save(out / "model.json"))}
    n = exp[0].n_samples
    files["force"] = str(write_series_force_h5(out / "force.h5", ide, shape=(len(exp), n),
                                               sample_rate_hz=exp[0].sample_rate_hz,
                                               inputs=paths, origin=origin))
    if figures:
        files.update(figures(ide, cal, out))
    result = result_record(ide, cal, input_path=paths[0], row=None,
                           runtime_s=time.perf_counter() - t0)
    result["input"] = [str(p.resolve()) for p in paths]
    result["joint"] = {"n_observations": len(exp),
                       "inputs": [str(p.resolve()) for p in paths],
                       "origin": [list(o) for o in origin],
                       "rest_gaps_m": np.asarray(exp.gaps_m, float).tolist(),
                       "length_unit_m": ide.joint_.problem.length_m,
                       "drive_ratios": np.asarray(ide.joint_.problem.drive_ratios,
                                                  float).tolist(),
                       "offsets": ide.joint_.problem.offsets.tolist(),
                       "phase": jsonable(ide.joint_.phase_info)}
    result["files"] = {**files, "result": str(out / "result.json")}
    write_json(out / "result.json", result)
    return {**result, "identifier": ide}


def write_series_force_h5(path: str | os.PathLike[str], ide: ForceIdentifier,
                          trace: Trace | None = None, *, shape: tuple[int, int] | None = None,
                          sample_rate_hz: float | None = None,
                          inputs: Sequence[PathLike] = (),
                          origin: Sequence[tuple[int, int]] = ()) -> Path:
    """Force of a joint fit aligned with a series' ``deflection_m`` (n_points, n), atomically.

    Without ``trace`` (observations of several files), ``shape`` (n_obs, n) and
    ``sample_rate_hz`` give the layout; ``inputs`` (the files) and ``origin`` ((file index,
    row) per observation) are then stored as attribute and dataset ``origin`` (n_obs, 2).
    """
    sc = ide.model_.scales
    if trace is not None:
        shape, sample_rate_hz = trace.deflection_m.shape, trace.sample_rate_hz
    assert shape is not None and sample_rate_hz is not None
    n = shape[1]
    z = np.asarray(ide.joint_.problem.length_m, float)
    gaps = np.array([o.gap for o in ide.joint_.problem.observations])
    series, quoted, fixed = _quoted_force(ide, sc.force)
    series["gap_m"] = (gaps[:, None] - np.asarray(ide.state_x_, float)) * z
    path = Path(path)
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        for key, value in series.items():
            assert value.shape == tuple(shape), (key, value.shape)
            ds = f.create_dataset(key, data=value)
            ds.attrs["unit"] = "m" if key == "gap_m" else "N"
        ds = f.create_dataset("time_s", data=np.arange(n) / sample_rate_hz)
        ds.attrs["unit"] = "s"
        if inputs:
            f.attrs["inputs"] = [str(Path(p).resolve()) for p in inputs]
            f.create_dataset("origin", data=np.asarray(origin, dtype=np.int64))
            f["origin"].attrs["description"] = "(index in inputs, row of that file)"
        f.attrs["format"] = "afmlearn-force"
        f.attrs["afmlearn_version"] = afmlearn.__version__
        f.attrs["row"] = -1
        f.attrs["joint"] = True
        _equation_attrs(f, ide, quoted, fixed)
        f.attrs["band"] = (fixed.band if fixed is not None and fixed.force is not None else
                           "95 % simultaneous profile-likelihood band of the output-error "
                           "fit (the exponent's profile and each point's Gauss-Newton band in "
                           "a0 and the coefficients)" if ide.joint_.output_error is not None else
                           "2.5 / 97.5 % over the bootstrap models")
        f.attrs["nan_means"] = "force band undefined (no bootstrap)"
    return path


def _quoted_force(ide: ForceIdentifier, force_n: float
                  ) -> tuple[dict[str, Any], Any, Any]:
    """force.h5's force datasets [N]: the quoted law's force and band (the law re-fitted at a
    fixed exponent when the data do not bound it, with the fitted law's force as
    ``fitted_force_n``), the quoted model and the fixed-exponent law (or None)."""
    fixed = getattr(ide, "fixed_exponent_", None)
    if fixed is not None and fixed.force is not None and fixed.model is not None:
        fo = fixed.force
        return ({"force_n": np.asarray(fo["force"], float) * force_n,
                 "force_lo_n": np.asarray(fo["lo"], float) * force_n,
                 "force_hi_n": np.asarray(fo["hi"], float) * force_n,
                 "fitted_force_n": np.asarray(ide.force_, float) * force_n},
                fixed.model, fixed)
    return ({"force_n": np.asarray(ide.force_, float) * force_n,
             "force_lo_n": np.asarray(ide.force_lo_, float) * force_n,
             "force_hi_n": np.asarray(ide.force_hi_, float) * force_n}, ide.model_, None)


def _equation_attrs(f: Any, ide: ForceIdentifier, quoted: Any, fixed: Any) -> None:
    """The quoted law's equation (and, when the exponent is fixed, the fitted one)."""
    f.attrs["equation"] = quoted.equation()
    f.attrs["equation_si"] = quoted.equation_si()
    if fixed is not None:
        f.attrs["exponent_fixed"] = float(fixed.exponent)
        f.attrs["fitted_equation"] = ide.model_.equation()
        f.attrs["fitted_equation_si"] = ide.model_.equation_si()


# ---------------------------------------------------------------------------- records
def result_record(ide: ForceIdentifier, cal: Calibrated, *, input_path: str | os.PathLike[str],
                  row: int | None, runtime_s: float) -> dict[str, Any]:
    """The JSON-able content of ``result.json`` for a fitted identifier."""
    model = ide.model_
    bands = model.coefficient_bands
    si = model.si_terms()
    summary = jsonable(ide.summary_)
    # an exponent the data do not bound is not quoted: the law at the sphere's 1.5 instead
    fixed = ide.fixed_exponent_ if hasattr(ide, "fixed_exponent_") else fixed_exponent_law(ide)
    quoted = model if fixed is None or fixed.model is None else fixed.model
    if fixed is not None:
        summary["interaction_exponent_fixed"] = fixed.exponent
        summary["interaction_exponent_note"] = fixed.text
    coefficients = []
    for j, (name, c) in enumerate(zip(model.library.names, model.coefficients, strict=True)):
        scale = si[j]["coefficient"] / c if c != 0 else math.nan
        entry: dict[str, Any] = {"term": name, "coefficient": float(c),
                                 "coefficient_si": si[j]["coefficient"], "unit_si": si[j]["unit"]}
        if bands is not None:
            entry["band"] = [float(bands[0, j]), float(bands[1, j])]
            entry["band_si"] = sorted([float(bands[0, j] * scale), float(bands[1, j] * scale)])
        coefficients.append(entry)
    return {
        "format": RESULT_FORMAT,
        "afmlearn_version": afmlearn.__version__,
        "input": str(Path(input_path).resolve()),
        "row": row,
        "equation": quoted.equation(),
        "equation_si": quoted.equation_si(),
        # the fitted law (model.json, force.h5); differs from "equation" only when the
        # exponent is fixed (exponent_fixed)
        "fitted_equation": model.equation(),
        "fitted_equation_si": model.equation_si(),
        "exponent_fixed": None if fixed is None else jsonable(fixed.record()),
        "si_terms": si,
        "lever": {"stiffness": model.stiffness, "damping": model.damping,
                  "drive_amplitude": model.drive_amplitude, "drive_phase_rad": model.drive_phase,
                  "omega": model.omega, "a0": model.a0, "gap": model.gap},
        "coefficients": coefficients,
        "summary": summary,
        "warnings": list(ide.warnings_),
        "calibration": calibration_record(cal),
        "selection": {
            "objectives": list(ide.objectives_),
            "knee_index": int(ide.knee_index_),
            "ic_index": int(ide.ic_index_),
            "ic": "aicc",
            "ic_equation": ide.ic_model_.equation(),
            "periodic": bool(ide.periodic_),
            "heldout_start": int(ide.heldout_start_),
            "a0_profile": jsonable(np.asarray(ide.a0_profile_).tolist()),
            "candidates": candidates_table(ide),
        },
        "runtime_s": float(runtime_s),
    }


def candidates_table(ide: ForceIdentifier) -> list[dict[str, Any]]:
    """One row per candidate support: n_terms, cv_error, state_error, (force_error), aicc, terms.

    Term names are ``LINEAR_TERMS`` followed by the identifier's library names (force terms at
    the candidates' common ``a0``); a candidate whose width does not match gets ``term_<j>``.
    """
    library = ide.library if ide.library is not None else AFMLibrary.standard()
    names = list(LINEAR_TERMS) + list(library.names)
    rows = []
    for i, c in enumerate(ide.candidates_):
        coef = np.asarray(c.coef).reshape(-1)
        labels = names if coef.size == len(names) else [f"term_{j}" for j in range(coef.size)]
        rows.append({
            "index": i,
            "n_terms": int(c.n_terms),
            "cv_error": float(c.cv_error),
            "state_error": float(c.scores.get("state_error", math.nan)),
            "force_error": float(c.scores.get("force_error", math.nan)),
            "aicc": float(c.aicc),
            "terms": [labels[j] for j in np.flatnonzero(coef)],
            "threshold": float(c.threshold),
            "nu": float(c.nu),
            "knee": i == ide.knee_index_,
            "ic_choice": i == ide.ic_index_,
        })
    return jsonable(rows)


def calibration_record(cal: Calibrated) -> dict[str, Any]:
    """The calibration the identification used (dimensionless view and SI scales)."""
    sc = cal.scales
    gap = np.asarray(cal.gap, float)
    return jsonable({
        "spring_constant_n_per_m": sc.spring_constant,
        "resonance_frequency_hz": sc.resonance_frequency,
        "length_m": sc.length,
        "force_unit_n": sc.force,
        "energy_unit_j": sc.energy,
        "quality_factor": cal.quality_factor,
        "omega": cal.omega,
        "drive_amplitude": cal.drive_amplitude,
        "drive_source": cal.drive_source,
        "excitation": cal.excitation,
        "excitation_assumed": cal.excitation_assumed,
        "samples_per_period": cal.samples_per_period,
        "n_samples": cal.n_samples,
        "gap_constant": bool(gap.ndim == 0),
        "gap_mean": float(np.mean(gap)),
        "gap_min": float(np.min(gap)),
        "gap_max": float(np.max(gap)),
        "tip_radius": cal.tip_radius,
        "row": cal.row,
    })


# ---------------------------------------------------------------------------- writers
def write_force_h5(path: str | os.PathLike[str], ide: ForceIdentifier, cal: Calibrated,
                   trace: Trace, *, row: int | None = None) -> Path:
    """Write the force aligned with the input deflection (atomically).

    Parameters
    ----------
    path : str or os.PathLike
        HDF5 file to write.
    ide : ForceIdentifier
        Fitted on ``cal``.
    cal : Calibrated
        The dimensionless view of ``trace`` (row ``row``).
    trace : Trace
        The input (gives the output shape: ``trace.deflection_m.shape``).
    row : int, optional
        Identified row of a sweep.

    Returns
    -------
    pathlib.Path
    """
    shape = trace.deflection_m.shape
    sc = cal.scales
    n = cal.n_samples
    gap = np.broadcast_to(np.asarray(cal.gap, float), (n,))
    series, quoted, fixed = _quoted_force(ide, sc.force)
    series["gap_m"] = (gap - np.asarray(ide.state_x_, float)) * sc.length
    units = {k: "N" for k in series} | {"gap_m": "m"}
    band = (fixed.band if fixed is not None and fixed.force is not None
            else "the bagged models")
    desc = {"force_n": "identified tip-sample force (the quoted law), > 0 repulsive",
            "force_lo_n": f"2.5 % quantile of the force over {band}",
            "force_hi_n": f"97.5 % quantile of the force over {band}",
            "fitted_force_n": "force of the fitted law (model.json) whose exponent the data "
                              "do not bound",
            "gap_m": "instantaneous tip-sample gap z = rest gap - deflection (denoised)"}
    path = Path(path)
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        for key, value in series.items():
            assert value.shape == (n,), (key, value.shape)
            full = np.full(shape, np.nan)
            if row is None:
                full[...] = value
            else:
                full[row] = value
            ds = f.create_dataset(key, data=full)
            ds.attrs["unit"] = units[key]
            ds.attrs["description"] = desc[key]
        ds = f.create_dataset("time_s", data=np.arange(n) / trace.sample_rate_hz)
        ds.attrs["unit"] = "s"
        f.attrs["format"] = "afmlearn-force"
        f.attrs["afmlearn_version"] = afmlearn.__version__
        f.attrs["row"] = -1 if row is None else int(row)
        _equation_attrs(f, ide, quoted, fixed)
        f.attrs["heldout_start"] = int(ide.heldout_start_)
        f.attrs["nan_means"] = "force undefined (or row not identified)"
    return path
