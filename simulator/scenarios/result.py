"""The record a scenario returns (dimensionless, with labels and an SI view)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from .._scales import Scales
from ..labels import labels_to_si
from ..system import System

__all__ = ["SimulationResult"]


@final
@dataclass(frozen=True)
class SimulationResult:
    """Recorded samples of one trace, or of a sweep (leading axis = sweep point).

    Attributes
    ----------
    system : System
    scenario : str
        ``steady``, ``transient``, ``approach`` or ``sweep``.
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

    @property
    def deflection(self) -> NDArray[np.float64]:
        """Tip deflection ``sum_i q_i`` (towards the sample), shape (n,) or (P, n)."""
        return self.q.sum(axis=-2)

    @property
    def is_sweep(self) -> bool:
        return np.ndim(self.omega) == 1

    @property
    def tau(self) -> NDArray[np.float64]:
        """Sample times from the start of the recording, shape (n,)."""
        return self.dt * np.arange(self.q.shape[-1])

    def to_si(self, scales: Scales) -> dict[str, Any]:
        """SI arrays and calibration attributes (the trace-format fields).

        Returns a mapping with ``deflection_m``, ``force_n``, ``modal_m`` (modes first),
        ``gap_m`` (rest gap: float, or array when it varies), ``sample_rate_hz``,
        ``drive_frequency_hz`` and SI labels (``dissipated_energy_j`` ...).
        """
        ell = scales.length
        f0 = scales.resonance_frequency
        modal = np.moveaxis(self.q, -2, 0) * ell
        rg = self.rest_gap if not self.is_sweep else self.rest_gap[0]
        gap: float | NDArray = (float(rg[0]) * ell if np.ptp(rg) == 0.0 else rg * ell)
        return {
            "deflection_m": self.deflection * ell,
            "force_n": self.force * scales.force,
            "modal_m": modal,
            "gap_m": gap,
            "sample_rate_hz": f0 * 2.0 * np.pi / self.dt,
            "drive_frequency_hz": np.asarray(self.omega) * f0,
            "labels": labels_to_si(self.labels, scales),
        }
