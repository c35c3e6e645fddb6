"""A simulated lock-in curve as a :class:`afmlearn.io.Trace` (what ``simulate.py`` writes)."""

from __future__ import annotations

from typing import Any

import numpy as np

from afmlearn.io import Trace
from simulator import Scales, SimulationResult
from simulator.scenarios.lockin import CurveRecord

__all__ = ["curve_trace"]


def curve_trace(result: SimulationResult, scales: Scales, calibration: dict[str, Any], *,
                model: dict | None = None) -> tuple[Trace, dict[str, Any]]:
    """Trace (lock-in fields, no deflection) and summary metrics of a ``LockInCurve`` run.

    Parameters
    ----------
    result : SimulationResult
        With ``meta["curve"]`` (:class:`simulator.scenarios.CurveRecord`).
    scales : Scales
    calibration : dict
        Root attributes (``spring_constant_n_per_m`` ...), as for every simulated trace.
    model : dict or None
        The ``/labels`` model record. Unused: trace format v1 keeps labels only beside a
        deflection record, so a curve file carries no truth (benchmarks keep it in memory).

    Returns
    -------
    trace : Trace
        ``amplitude_m``, ``phase_rad``, ``z_piezo_m``, ``segment`` (n,), ``gap_m`` = the
        programmed piezo position, ``lockin_bandwidth_hz``; no labels.
    summary : dict
        The metrics ``afmlearn.simulate`` reports.
    """
    rec: CurveRecord = result.meta["curve"]
    ell, f0 = scales.length, scales.resonance_frequency
    li = result.meta["lockin"]
    dt_out = float(rec.tau[1] - rec.tau[0])
    trace = Trace(None, sample_rate_hz=f0 * 2.0 * np.pi / dt_out,
                  drive_frequency_hz=float(result.omega) * f0, gap_m=rec.z_piezo * ell,
                  amplitude_m=rec.amplitude * ell, phase_rad=rec.phase,
                  z_piezo_m=rec.z_piezo * ell, segment=rec.segment,
                  lockin_bandwidth_hz=float(li["bandwidth"]) * f0,
                  **calibration)
    summary = {"n_points": 1, "n_samples": int(rec.tau.size),
               "amplitude_m": float(np.min(rec.amplitude)) * ell,
               "contact_fraction": float(np.mean(result.contact)),
               "dissipated_energy_j": float("nan"),
               "peak_force_n": float(np.max(result.force)) * scales.force,
               "coupling_strength": 0.0, "regime": "curve"}
    return trace, summary
