"""The record a scenario returns (dimensionless, with labels and an SI view)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from .._scales import Scales
from ..labels import labels_to_si, recorded_drive_phase
from ..system import System

__all__ = ["SimulationResult"]


@final
@dataclass(frozen=True)
class SimulationResult:
    """Recorded samples of one trace, or of rows (a sweep or a set-point series).

    Rows have a leading axis: one per drive frequency (sweep) or rest gap (spectroscopy).

    Attributes
    ----------
    system : System
    scenario : str
        ``steady``, ``transient``, ``approach``, ``sweep`` or ``spectroscopy``.
    dt : float
        Sample interval (dimensionless, ``omega0 / f_s``).
    omega : float or ndarray, shape (P,)
        Drive frequency (per sweep point).
    q : ndarray, shape (M, n) or (P, M, n)
        Modal deflections.
    force : ndarray, shape (n,) or (P, n)
        True tip--sample force (> 0 repulsive).
    gap : ndarray, shape (n,) or (P, n)
        Instantaneous gap ``z``.
    rest_gap : ndarray, shape (n,) or (P, n)
        Rest gap ``g`` (undeflected cantilever).
    contact : ndarray of int8, shape (n,) or (P, n)
        Contact regime.
    phase : ndarray, shape (n,) or (P, n)
        Drive phase.
    labels : dict
        Scalars (or arrays (P,) for sweeps), see :mod:`simulator.labels`.
    meta : dict
        Scenario parameters.
    velocity : ndarray or None
        Modal velocities (shape of ``q``) when recorded.
    segment : ndarray of int8, shape (n,), or None
        For ramps: 0 while approaching, 1 while retracting.
    """

    system: System
    scenario: str
    dt: float
    omega: float | NDArray[np.float64]
    q: NDArray[np.float64]
    force: NDArray[np.float64]
    gap: NDArray[np.float64]
    rest_gap: NDArray[np.float64]
    contact: NDArray[np.int8]
    phase: NDArray[np.float64]
    labels: dict[str, Any]
    meta: dict[str, Any] = field(default_factory=dict)
    velocity: NDArray[np.float64] | None = None
    segment: NDArray[np.int8] | None = None

    @property
    def deflection(self) -> NDArray[np.float64]:
        """Tip deflection ``sum_i q_i`` (towards the sample), shape (n,) or (P, n)."""
        return self.q.sum(axis=-2)

    @property
    def is_sweep(self) -> bool:
        """True when the rows have their own drive frequency."""
        return np.ndim(self.omega) == 1

    @property
    def has_rows(self) -> bool:
        """True for a sweep or a set-point series (``q`` of shape (P, M, n))."""
        return self.q.ndim == 3

    @property
    def drive_phase(self) -> float | NDArray[np.float64]:
        """Recorded drive phase at the first sample (of each row) [rad], trace convention.

        See :func:`simulator.labels.recorded_drive_phase`; float, or shape (P,) for rows.
        """
        theta = self.phase[..., 0]
        if not self.is_sweep:
            return recorded_drive_phase(theta, self.system, float(self.omega))
        return np.array([recorded_drive_phase(t, self.system, float(w))
                         for t, w in zip(theta, np.asarray(self.omega), strict=True)])

    @property
    def tau(self) -> NDArray[np.float64]:
        """Sample times from the start of the recording, shape (n,)."""
        return self.dt * np.arange(self.q.shape[-1])

    def to_si(self, scales: Scales) -> dict[str, Any]:
        """SI arrays and calibration attributes (the trace-format fields).

        Returns a mapping with ``deflection_m``, ``force_n``, ``modal_m`` (modes first),
        ``gap_m`` (rest gap: float; shape (n,) when it varies in time; shape (P,) for a
        set-point series), ``sample_rate_hz``, ``drive_frequency_hz``, ``drive_phase_rad``
        (float or (P,)), ``segment`` (or None) and SI labels (``dissipated_energy_j`` ...).
        """
        ell = scales.length
        f0 = scales.resonance_frequency
        modal = np.moveaxis(self.q, -2, 0) * ell
        gap: float | NDArray
        if self.has_rows and np.all(np.ptp(self.rest_gap, axis=-1) == 0.0):
            per_row = self.rest_gap[:, 0]
            gap = float(per_row[0]) * ell if np.ptp(per_row) == 0.0 else per_row * ell
        else:
            rg = self.rest_gap[0] if self.has_rows else self.rest_gap
            gap = float(rg[0]) * ell if np.ptp(rg) == 0.0 else rg * ell
        return {
            "deflection_m": self.deflection * ell,
            "force_n": self.force * scales.force,
            "modal_m": modal,
            "gap_m": gap,
            "sample_rate_hz": f0 * 2.0 * np.pi / self.dt,
            "drive_frequency_hz": np.asarray(self.omega) * f0,
            "drive_phase_rad": self.drive_phase,
            "segment": self.segment,
            "labels": labels_to_si(self.labels, scales),
        }
