"""From a :class:`~afmlearn.identify.joint.JointResult` to the identifier's public outputs.

Pure functions: the identified model in the experiment's common units (``L_ref`` = mean rest
gap), the force on every sample of every observation with its bootstrap band, and the physical
summary with the contact exponent's interval and whether the data bound it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from simulator import Scales

from .force_band import conditional_band, profile_band
from .joint import JointResult
from .library import AFMLibrary, Constant, TermInput
from .model import IdentifiedModel

__all__ = ["joint_force", "joint_model", "joint_summary", "format_exponent", "orbit_inputs",
           "finite_number"]

FloatArray = NDArray[np.float64]


def joint_model(res: JointResult, coef: FloatArray, library: AFMLibrary, a0: float, *,
                bands: FloatArray | None = None, info: dict[str, Any] | None = None
                ) -> IdentifiedModel:
    """The identified law in common units; the drive is that of the first observation."""
    pb = res.problem
    n_lin = pb.n_lin
    cf = np.asarray(coef[n_lin:], float)
    keep = cf != 0
    if keep.any():
        lib, cf = library.subset(keep), cf[keep]
        bands = None if bands is None else bands[:, keep]
    else:
        lib, cf, bands = AFMLibrary([Constant()]), np.zeros(1), None
    o0 = pb.observations[0]
    if pb.rotated[0]:
        k = 0  # observation 0 is the first rotated one: its quadrature is column n_lever + 1
        amp = float(coef[2])
        quad = float(coef[3 + k])
        phase = float(pb.rotations[0]) + math.atan2(quad, amp)
        amp = math.hypot(amp, quad) * float(pb.drive_ratios[0])
    else:
        j = n_lin - 2 * int((~pb.rotated).sum())
        amp = math.hypot(coef[j], coef[j + 1])
        phase = math.atan2(coef[j + 1], coef[j])
    cal = o0.calibrated
    scales = Scales(spring_constant=cal.scales.spring_constant,
                    resonance_frequency=cal.scales.resonance_frequency, length=pb.length_m)
    return IdentifiedModel(library=lib, coefficients=cf, stiffness=-float(coef[1]),
                           damping=-float(coef[0]), drive_amplitude=float(amp),
                           drive_phase=float(phase), omega=o0.omega, a0=float(a0), gap=1.0,
                           scales=scales, coefficient_bands=bands, info=info or {})


def joint_force(res: JointResult) -> dict[str, FloatArray]:
    """Force [k L_ref] on every sample of every observation, shape (n_obs, n) each.

    Keys ``force``, ``lo``, ``hi``, ``x``, ``v`` (denoised deflection and rate), ``z`` (gap
    ``gap_i - x``). The 95 % band: with the output-error stage, the simultaneous
    profile-likelihood band of :func:`~afmlearn.identify.force_band.profile_band` (the
    exponent's profile and each point's Gauss--Newton band in ``a0`` and the coefficients;
    without a profile, the estimate's Gauss--Newton band); else 2.5 / 97.5 % over the
    bootstrap models (NaN without bootstrap).
    """
    pb = res.problem
    n_lin = pb.n_lin
    out: dict[str, list[FloatArray]] = {k: [] for k in ("force", "lo", "hi", "x", "v", "z")}
    band = _output_error_band(res)
    for i, o in enumerate(pb.observations):
        x, v = o.denoised.x, o.denoised.v
        z = o.gap - x
        th = res.library.evaluate(TermInput(z=z, zdot=-v, x=x, a0=res.a0))
        f = th @ res.coef[n_lin:]
        if band is not None:
            lo, hi = band["lo"][i], band["hi"][i]
        elif res.samples.shape[0] >= 5:
            fs = res.samples[:, n_lin:] @ th.T
            lo, hi = np.percentile(fs, [2.5, 97.5], axis=0)
        else:
            lo = hi = np.full_like(f, np.nan)
        for k, val in zip(("force", "lo", "hi", "x", "v", "z"), (f, lo, hi, x, v, z),
                          strict=True):
            out[k].append(val)
    return {k: np.stack(v) for k, v in out.items()}


def orbit_inputs(res: JointResult) -> list[TermInput]:
    """The denoised orbit of every observation as library input (``a0`` of the fit)."""
    return [TermInput(z=o.gap - o.denoised.x, zdot=-o.denoised.v, x=o.denoised.x, a0=res.a0)
            for o in res.problem.observations]


def _output_error_band(res: JointResult) -> dict[str, list[FloatArray]] | None:
    """The output-error fit's 95 % force band (None without that stage)."""
    oe = res.output_error
    if oe is None:
        return None
    ins = orbit_inputs(res)
    ex = res.exponent or {}
    if ex.get("fits"):
        band = profile_band(ex, oe, ins)
        if band is not None:
            return band
    return conditional_band(oe, ins)


def joint_summary(res: JointResult, model: IdentifiedModel, forces: dict[str, FloatArray]
                  ) -> dict[str, Any]:
    """Physical outputs over all observations, dimensionless and SI.

    ``interaction_exponent``: the dominant ``delta^p`` of the chosen support;
    ``interaction_exponent_interval``: its 95 % profile-likelihood interval over the joint fit;
    ``interaction_exponent_bounded``: False when the interval reaches the profiled range's end
    (the data do not bound the exponent); ``interaction_exponent_profile_best``: the exponent
    at the profile's minimum.
    """
    pb = res.problem
    sc = model.scales
    f, z = forces["force"], forces["z"]
    dtau = float(pb.observations[0].tau[1] - pb.observations[0].tau[0])
    e_diss = []
    contact = []
    for i, o in enumerate(pb.observations):
        n_per = o.x.size / o.calibrated.samples_per_period
        e_diss.append(float(-np.sum(f[i] * -forces["v"][i]) * dtau / n_per))
        contact.append(float(np.mean(z[i] <= res.a0)))
    ex = res.exponent
    expo = None if ex is None else float(res.library.terms[ex["term_index"]].p)
    if expo is None:
        for t in model.library.terms:
            if hasattr(t, "p") and type(t).__name__ == "Indentation":
                expo = float(t.p)
    interval = None if ex is None else tuple(float(v) for v in ex["interval"])
    rec = np.where(pb.rotated, pb.rotations, np.nan)
    return {
        "interaction_exponent": expo,
        "interaction_exponent_interval": interval,
        "interaction_exponent_bounded": None if ex is None else bool(ex["bounded"]),
        "interaction_exponent_profile_best": None if ex is None else ex["best_exponent"],
        "interaction_exponent_cv_interval": None if ex is None else ex["cv_interval"],
        "interaction_exponent_cv_bounded": None if ex is None else ex["cv_bounded"],
        "a0": model.a0, "a0_m": model.a0 * sc.length,
        "n_observations": pb.n_obs,
        "rest_gaps_m": [o.gap * pb.length_m for o in pb.observations],
        # file convention (design.md section 2): drive ∝ cos(2 pi f t + drive_phase_rad)
        "drive_phases_rad": [float(-p) for p in rec],
        "drive_phase_method": res.phase_info.get("method"),
        "dissipated_energy_per_cycle": e_diss,
        "dissipated_energy_per_cycle_j": [e * sc.energy for e in e_diss],
        "peak_repulsive_force": float(max(np.max(f), 0.0)),
        "peak_repulsive_force_n": float(max(np.max(f), 0.0)) * sc.force,
        "peak_attractive_force_n": float(min(np.min(f), 0.0)) * sc.force,
        "contact_fraction": contact,
        "refined": bool(res.refined),
        "state_accuracy_heldout": None,
    }


def format_exponent(summary: dict[str, Any]) -> str:
    """One line: the exponent with its 95 % interval, or why there is none; when the data do
    not bound it, the summary's ``interaction_exponent_note`` (the exponent the quoted
    equation uses, fixed, with the interval)."""
    p = summary.get("interaction_exponent")
    iv = summary.get("interaction_exponent_interval")
    if p is None:
        return "interaction exponent: no contact term identified"
    if iv is None or not all(finite_number(v) for v in iv):
        return f"interaction exponent {p:.2f} (no profile interval)"
    note = summary.get("interaction_exponent_note")
    if note:  # not bounded: what the quoted equation uses (afmlearn.identify.fixed_exponent)
        txt = str(note)
    else:
        txt = f"interaction exponent {p:.2f} (95 % profile interval {iv[0]:.2f}-{iv[1]:.2f})"
        bounded = summary.get("interaction_exponent_bounded")
        if bounded is None:  # the single-orbit profile spans 0.5 ... 4
            bounded = iv[0] > 0.5 + 1e-9 and iv[1] < 4.0 - 1e-9
        if not bounded:
            txt += (": NOT bounded by the data (the interval reaches the end of the profiled "
                    "range)")
        best = summary.get("interaction_exponent_profile_best")
        if best is not None and not iv[0] <= p <= iv[1]:
            txt += f"; the profile's best exponent is {best:.2f}, not the selected model's"
    cv = summary.get("interaction_exponent_cv_interval")
    if cv is not None and all(finite_number(v) for v in cv):
        txt += (f"; cross-validated over set-points {cv[0]:.2f}-{cv[1]:.2f}"
                + ("" if summary.get("interaction_exponent_cv_bounded") else " (NOT bounded)"))
    return txt


def finite_number(v: Any) -> bool:
    """A finite number (JSON turns NaN into None: a summary read back has None there)."""
    return isinstance(v, int | float) and math.isfinite(v)
