"""Identify the tip--sample force of one recorded trace file and write the results.

:func:`identify_trace` is the one function behind ``scripts/identify.py``. It reads a trace
format v1 file **without its /labels group** (``afmlearn.io.read_trace(path)``; the file name is
never interpreted), fits a :class:`ForceIdentifier` and writes into ``out_dir`` (each file
atomically: temporary sibling + ``os.replace``):

``result.json``
    The equation (dimensionless and SI), the SI terms, the coefficients with their bagging
    bands, the physical summary (interaction exponent, dissipated energy per cycle, peak
    repulsive force, contact time, held-out state accuracy, ...), warnings, the calibration
    used, the candidates table with the knee and AICc choices, runtime, afmlearn version and
    the input path.
``model.json``
    The chosen :class:`IdentifiedModel` (``IdentifiedModel.load`` reloads it).
``force.h5``
    ``force_n`` [N] aligned sample by sample with the input deflection (same shape; NaN where
    the force is undefined and, for a sweep, in every row but the identified one),
    ``force_lo_n`` / ``force_hi_n`` (95 % bagging band), ``gap_m`` (instantaneous tip--sample
    gap of the denoised orbit, same shape) and ``time_s`` (n,); units in attributes.
``pareto.png``, ``coefficients.png``, ``orbit.png``, ``force.png``
    Figures (:mod:`afmlearn.plots.identify`), unless ``figures=False``.

Sweeps: one row is identified; ``row`` is then required (a ValueError lists the valid range).
The row cannot be chosen from the data without identifying every row, and picking one silently
would hide which drive frequency the result belongs to.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

import afmlearn
from afmlearn.io import Trace, jsonable, read_trace, write_json
from afmlearn.io._atomic import atomic_path
from afmlearn.preprocess import Calibrated, calibrate, check_trace, checked_row

from .identifier import LINEAR_TERMS, ForceIdentifier
from .library import AFMLibrary

__all__ = ["identify_trace", "candidates_table", "calibration_record", "write_force_h5",
           "write_json", "jsonable", "RESULT_FORMAT"]

RESULT_FORMAT = "afmlearn-identify-result"


def identify_trace(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *,
                   row: int | None = None, identifier: ForceIdentifier | None = None,
                   figures: bool = True) -> dict[str, Any]:
    """Identify the force of one trace file (one row of a sweep) and write the results.

    Parameters
    ----------
    path : str or os.PathLike
        Trace file, format v1. Its ``/labels`` group is never read.
    out_dir : str or os.PathLike
        Output folder (created if missing); existing result files are replaced.
    row : int, optional
        Row of a sweep, in ``[0, n_points)``; required for sweeps, must be None otherwise.
    identifier : ForceIdentifier, optional
        Settings (unfitted; it is cloned by reference, i.e. fitted in place); default
        ``ForceIdentifier()``.
    figures : bool
        Also write the PNG figures.

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
    path = Path(path)
    out = Path(out_dir)
    trace = read_trace(path)                      # labels=False: /labels is never opened
    row = checked_row(trace, row)
    ide = identifier if identifier is not None else ForceIdentifier()
    if not isinstance(ide, ForceIdentifier):
        raise ValueError(f"identifier must be a ForceIdentifier, got {type(ide).__name__}")
    check_trace(trace, row=row)
    cal = calibrate(trace, row=row)
    ide.fit(cal)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    files["model"] = str(ide.model_.save(out / "model.json"))
    files["force"] = str(write_force_h5(out / "force.h5", ide, cal, trace, row=row))
    if figures:
        from afmlearn.plots.identify import (
            plot_coefficients,
            plot_force,
            plot_orbit,
            plot_pareto,
        )
        files["pareto"] = str(plot_pareto(ide, out / "pareto.png"))
        files["coefficients"] = str(plot_coefficients(ide.model_, None,
                                                      out / "coefficients.png"))
        files["orbit"] = str(plot_orbit(ide, cal.x, out / "orbit.png", calibrated=cal))
        files["force_figure"] = str(plot_force(ide, out / "force.png", calibrated=cal))
    result = result_record(ide, cal, input_path=path, row=row,
                           runtime_s=time.perf_counter() - t0)
    result["files"] = {**files, "result": str(out / "result.json")}
    write_json(out / "result.json", result)
    return {**result, "identifier": ide}


# ---------------------------------------------------------------------------- records
def result_record(ide: ForceIdentifier, cal: Calibrated, *, input_path: str | os.PathLike[str],
                  row: int | None, runtime_s: float) -> dict[str, Any]:
    """The JSON-able content of ``result.json`` for a fitted identifier."""
    model = ide.model_
    bands = model.coefficient_bands
    si = model.si_terms()
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
        "equation": model.equation(),
        "equation_si": model.equation_si(),
        "si_terms": si,
        "lever": {"stiffness": model.stiffness, "damping": model.damping,
                  "drive_amplitude": model.drive_amplitude, "drive_phase_rad": model.drive_phase,
                  "omega": model.omega, "a0": model.a0, "gap": model.gap},
        "coefficients": coefficients,
        "summary": jsonable(ide.summary_),
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
    series = {
        "force_n": np.asarray(ide.force_, float) * sc.force,
        "force_lo_n": np.asarray(ide.force_lo_, float) * sc.force,
        "force_hi_n": np.asarray(ide.force_hi_, float) * sc.force,
        "gap_m": (gap - np.asarray(ide.state_x_, float)) * sc.length,
    }
    units = {"force_n": "N", "force_lo_n": "N", "force_hi_n": "N", "gap_m": "m"}
    desc = {"force_n": "identified tip-sample force, > 0 repulsive",
            "force_lo_n": "2.5 % quantile of the force over the bagged models",
            "force_hi_n": "97.5 % quantile of the force over the bagged models",
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
        f.attrs["equation"] = ide.model_.equation()
        f.attrs["equation_si"] = ide.model_.equation_si()
        f.attrs["heldout_start"] = int(ide.heldout_start_)
        f.attrs["nan_means"] = "force undefined (or row not identified)"
    return path
