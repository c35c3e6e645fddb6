"""From an :class:`~afmlearn.identify.single.OrbitResult` to the identifier's public
single-orbit outputs.

Pure functions: the force on every sample of the record with its bootstrap band
(:func:`orbit_force`) and the physical summary with the contact exponent's profile interval
(:func:`orbit_summary`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from afmlearn.metrics import nrmse

from .library import AFMLibrary
from .library._kernel import force_series
from .model import IdentifiedModel
from .selection import profile_interval
from .single import HeldoutStateError, OrbitExponentProfile, OrbitResult
from .single_problem import N_LIN, OrbitProblem
from .summary import summarize

__all__ = ["orbit_force", "orbit_summary"]

FloatArray = NDArray[np.float64]


def orbit_force(problem: OrbitProblem, model: IdentifiedModel, library: AFMLibrary,
                samples: FloatArray | None) -> dict[str, FloatArray]:
    """The identified force on every sample and its 95 % bootstrap band.

    Parameters
    ----------
    library : AFMLibrary
        Columns of the bootstrap ``samples`` (the final support, before zero terms drop).
    samples : ndarray, shape (n_boot, n_lin + n_terms), or None
        Bagged coefficients (fewer than 5: no band).

    Returns
    -------
    dict
        ``x``, ``v`` (denoised state), ``z``, ``zdot`` (gap and its rate), ``force``, ``lo``,
        ``hi`` (band; NaN without one), each shape (n,), dimensionless.
    """
    cal = problem.calibrated
    xs, vs = problem.full_state()
    gap = np.broadcast_to(np.asarray(cal.gap, float), xs.shape)
    z, zd = gap - xs, -vs
    force = model.force(z, zd, xs)
    lo = hi = np.full_like(force, np.nan)
    if samples is not None and len(samples) >= 5:
        kinds, p1, p2 = library.encode()  # bagged samples use this layout
        hf = problem.denoised.harmonic_fit
        if problem.periodic and hf is not None:
            # periodic: the bands are functions of the drive phase; evaluate on one
            # period and interpolate (exact up to the 4096-point phase grid)
            m = 4096
            ph = 2 * np.pi * np.arange(m + 1) / m
            tg = ph / hf.base_frequency
            xg, vg = hf.evaluate(tg), hf.evaluate(tg, 1)
            gz, gzd = float(np.mean(gap)) - xg, -vg
            fs = np.array([force_series(kinds, p1, p2, np.ascontiguousarray(c[N_LIN:]),
                                        model.a0, gz, gzd, xg) for c in samples])
            lo_g, hi_g = np.percentile(fs, [2.5, 97.5], axis=0)
            phase = np.mod(hf.base_frequency * cal.tau, 2 * np.pi)
            lo, hi = np.interp(phase, ph, lo_g), np.interp(phase, ph, hi_g)
        else:
            fs = np.array([force_series(kinds, p1, p2, np.ascontiguousarray(c[N_LIN:]),
                                        model.a0, np.ascontiguousarray(z),
                                        np.ascontiguousarray(zd), xs) for c in samples])
            lo, hi = np.percentile(fs, [2.5, 97.5], axis=0)
    return {"x": xs, "v": vs, "z": z, "zdot": zd, "force": force, "lo": lo, "hi": hi}


def orbit_summary(res: OrbitResult, model: IdentifiedModel, forces: dict[str, FloatArray], *,
                  state: HeldoutStateError, exponent: OrbitExponentProfile,
                  true_force: FloatArray | None = None
                  ) -> tuple[dict[str, Any], FloatArray | None]:
    """Physical summary (:func:`~afmlearn.identify.summary.summarize`) and exponent profile.

    Adds the dominant contact exponent's 95 % profile interval
    (``interaction_exponent_interval``, :func:`~afmlearn.identify.selection.profile_interval`
    over the problem's rows) and whether the profile's grid bounds it, and with
    ``true_force`` (n,) its NRMSE against the model's force. Returns the summary and the
    profile ``(p, RSS)`` of shape (n_p, 2) (None without a contact term).
    """
    pb = res.problem
    summary = summarize(model, z=forces["z"], zdot=forces["zdot"], force=forces["force"],
                        cal=pb.calibrated, state_error=state.run(pb, model))
    prof = exponent.run(pb, res.library, model.a0, summary.get("interaction_exponent"))
    if prof is not None:
        n_rows = pb.design(res.library, model.a0).y.size
        iv = profile_interval(prof, n_rows)
        summary["interaction_exponent_interval"] = iv
        grid = prof[:, 0]
        summary["interaction_exponent_bounded"] = bool(
            iv[0] > grid.min() + 1e-9 and iv[1] < grid.max() - 1e-9)
    if true_force is not None:
        summary["force_nrmse_vs_truth"] = float(nrmse(forces["force"], true_force))
    return summary, prof
