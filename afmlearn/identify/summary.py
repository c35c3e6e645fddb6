"""Physical outputs of an identified model on its orbit: summary numbers, force vs gap."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from afmlearn.preprocess import Calibrated

from .library import Indentation, TermInput
from .model import IdentifiedModel

__all__ = ["force_vs_gap", "summarize"]

FloatArray = NDArray[np.float64]


def summarize(model: IdentifiedModel, *, z: FloatArray, zdot: FloatArray, force: FloatArray,
              cal: Calibrated, state_error: float) -> dict[str, Any]:
    """Physical outputs of an identified model on its orbit (dimensionless and SI)."""
    sc = cal.scales
    spp = cal.samples_per_period
    n = force.size
    n_per = n / spp
    dtau = float(cal.tau[1] - cal.tau[0])
    # energy delivered to the sample per cycle: -oint F dz = -int F z' dtau
    e_diss = float(-np.sum(force * zdot) * dtau / n_per)
    contact = z <= model.a0
    expo = None
    best = 0.0
    for c, t in zip(model.coefficients, model.library.terms, strict=True):
        if isinstance(t, Indentation):
            contrib = abs(c) * float(np.sqrt(np.mean(t.evaluate(
                TermInput(z=z, zdot=zdot, x=model.gap - z, a0=model.a0)) ** 2)))
            if contrib > best:
                best, expo = contrib, float(t.p)
    period_s = 1.0 / (cal.omega * sc.resonance_frequency)
    return {
        "interaction_exponent": expo,
        "a0": model.a0, "a0_m": model.a0 * sc.length,
        "dissipated_energy_per_cycle": e_diss,
        "dissipated_energy_per_cycle_j": e_diss * sc.energy,
        "peak_repulsive_force": float(max(np.max(force), 0.0)),
        "peak_repulsive_force_n": float(max(np.max(force), 0.0)) * sc.force,
        "peak_attractive_force_n": float(min(np.min(force), 0.0)) * sc.force,
        "contact_fraction": float(np.mean(contact)),
        "contact_time_s": float(np.mean(contact)) * period_s,
        "state_error_heldout": state_error,
        "state_accuracy_heldout": 1.0 - state_error,
    }


def force_vs_gap(z: FloatArray, zdot: FloatArray, force: FloatArray, *, n_bins: int = 200
                 ) -> dict[str, FloatArray]:
    """Force against gap on approach (``z' < 0``) and retraction (``z' > 0``), binned means.

    Returns arrays of shape (n_bins,): ``gap`` (bin centres) and ``approach``/``retract``
    (NaN in empty bins).
    """
    edges = np.linspace(np.min(z), np.max(z), n_bins + 1)
    centres = 0.5 * (edges[1:] + edges[:-1])
    out: dict[str, FloatArray] = {"gap": centres}
    for key, m in (("approach", zdot < 0), ("retract", zdot >= 0)):
        idx = np.clip(np.digitize(z[m], edges) - 1, 0, n_bins - 1)
        s = np.bincount(idx, weights=force[m], minlength=n_bins)
        c = np.bincount(idx, minlength=n_bins)
        out[key] = np.where(c > 0, s / np.maximum(c, 1), np.nan)
    return out
