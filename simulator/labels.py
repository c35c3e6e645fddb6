"""Per-trace labels computed from integrated segments (dimensionless).

Definitions (used everywhere in afmlearn):

* ``dissipated_energy``: energy delivered to the sample per drive cycle, ``-oint F dz``,
  averaged over the recorded cycles (units ``k L_ref**2``; 0 for conservative models).
* ``contact_fraction``: share of time spent in the contact regime.
* ``coupling_strength``: share of the tip motion carried by modes >= 2,
  ``var(sum_{i>=2} q_i) / (var(q_1) + var(sum_{i>=2} q_i))`` in [0, 1].
* ``regime``: ``free`` (no force), ``attractive`` (force, never repulsive, never in contact),
  ``repulsive`` (intermittent contact, tapping; for laws without a contact branch such as
  Lennard-Jones: the force turns repulsive on part of the orbit) or ``permanent_contact``.
* ``amplitude``, ``phase``: first-harmonic amplitude and phase lag of the deflection relative
  to the drive phase (lock-in over the recorded span).
* ``drive_energy``, ``damping_energy``: energy put in by the drive and lost to the
  cantilever's own damping per drive cycle; in a steady state
  ``drive_energy = damping_energy + dissipated_energy``.

The recorded drive phase (trace attribute ``drive_phase_rad``, design.md section 2) is the
phase of the drive written as ``cos(Omega tau + phase)``, positive towards the sample:
``theta`` for a tip force ``B cos(theta)``, ``theta - pi/2`` for a base motion
``y sin(theta)`` (:func:`recorded_drive_phase`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._scales import Scales
from .integrate.state import Segment
from .system import System

__all__ = ["segment_labels", "trace_labels", "labels_to_si", "coupling_strength", "lock_in",
           "recorded_drive_phase"]


def lock_in(x: NDArray[np.float64], phase: NDArray[np.float64], harmonic: int = 1) -> complex:
    """Complex amplitude of ``x`` at ``harmonic`` of the drive: ``x ~ Re(A e^{i h theta})``.

    Parameters
    ----------
    x : ndarray, shape (n,)
    phase : ndarray, shape (n,)
        Drive phase ``theta`` at each sample.
    """
    return complex(2.0 * np.mean(x * np.exp(-1j * harmonic * phase)))


def recorded_drive_phase(theta: float | NDArray[np.float64], system: System,
                         omega: float) -> float | NDArray[np.float64]:
    """Drive phase in the trace convention, wrapped to (-pi, pi].

    The modal drive of the fundamental is ``c cos(theta) + s sin(theta) = r cos(theta - a)``
    with ``a = atan2(s, c)`` (0 for a tip force, pi/2 for a base motion), so the drive is
    ``cos(Omega tau + phase)`` with ``phase = theta - a`` at ``tau = 0``.

    Parameters
    ----------
    theta : float or ndarray
        Simulator drive phase ``theta`` at the sample(s) of interest [rad].
    system : System
        Supplies the excitation and the cantilever.
    omega : float
        Drive frequency ``Omega``.
    """
    c, s = system.excitation.modal_drive(system.cantilever, omega)
    offset = math.atan2(float(s[0]), float(c[0])) if (c[0] or s[0]) else 0.0
    wrapped = np.angle(np.exp(1j * (np.asarray(theta, dtype=float) - offset)))
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def coupling_strength(q: NDArray[np.float64]) -> float:
    """Share of tip motion carried by modes >= 2; ``q`` has shape (n_modes, n)."""
    if q.shape[0] < 2:
        return 0.0
    v1 = float(np.var(q[0]))
    vh = float(np.var(q[1:].sum(axis=0)))
    tot = v1 + vh
    return vh / tot if tot > 0 else 0.0


def segment_labels(seg: Segment, b: int = 0) -> dict[str, Any]:
    """Scalar labels of trajectory ``b`` of a recorded segment."""
    return trace_labels(q=seg.q[b], force=seg.force[b], gap=seg.gap[b], phase=seg.phase[b],
                        work=seg.work[b], dt=seg.dt, omega=float(seg.omega[b]),
                        drive_cos=seg.drive_cos[b], drive_sin=seg.drive_sin[b])


def trace_labels(*, q: NDArray[np.float64], force: NDArray[np.float64],
                 gap: NDArray[np.float64], phase: NDArray[np.float64],
                 work: NDArray[np.float64], dt: float, omega: float,
                 drive_cos: NDArray[np.float64] | None = None,
                 drive_sin: NDArray[np.float64] | None = None) -> dict[str, Any]:
    """Scalar labels of one recorded trace.

    Parameters
    ----------
    q : ndarray, shape (n_modes, n)
        Modal deflections.
    force, gap, phase : ndarray, shape (n,)
        Tip--sample force, gap ``z`` and drive phase at each sample.
    work : ndarray, shape (5,)
        Work integrals accumulated over the trace (see ``integrate/_kernel.py``).
    dt : float
        Sample interval.
    omega : float
        Drive frequency.
    drive_cos, drive_sin : ndarray, shape (n,), optional
        ``cos(phase)``, ``sin(phase)`` if already computed (saves the complex lock-in).
    """
    n = q.shape[-1]
    duration = n * dt
    cycles = duration * omega / (2.0 * math.pi)
    x = q.sum(axis=0)
    cf = float(work[4] / duration)
    fmax = float(np.max(np.abs(force)))
    if fmax == 0.0:
        regime = "free"
    elif cf <= 0.0 and float(np.max(force)) <= 0.0:
        regime = "attractive"
    elif cf >= 1.0 - 1e-9:
        regime = "permanent_contact"
    else:
        regime = "repulsive"
    # lock-in over whole periods only
    # (rounded: truncating 1999.9999 samples to 1999 left a partial period whose bias
    # depended on the drive phase at the first sample)
    spp = 2.0 * math.pi / (omega * dt)
    n_whole = min(n, int(round(math.floor(n / spp + 1e-9) * spp)))
    sl = slice(0, n_whole if n_whole > 0 else n)
    if drive_cos is not None and drive_sin is not None:
        xs = x[sl]
        a1 = complex(2.0 * np.mean(xs * drive_cos[sl]), -2.0 * np.mean(xs * drive_sin[sl]))
    else:
        a1 = lock_in(x[sl], phase[sl])
    return {
        "dissipated_energy": float(work[3] / cycles) if cycles > 0 else 0.0,
        "drive_energy": float(work[0] / cycles) if cycles > 0 else 0.0,
        "damping_energy": float(work[1] / cycles) if cycles > 0 else 0.0,
        "contact_fraction": cf,
        "coupling_strength": coupling_strength(q),
        "regime": regime,
        "amplitude": abs(a1),
        "phase": float(-np.angle(a1)),
        "mean_deflection": float(np.mean(x)),
        "min_gap": float(np.min(gap)),
        "max_force": float(np.max(force)),
        "min_force": float(np.min(force)),
    }


#: dimensionless label -> (SI name, ``Scales`` attribute giving its unit, or None)
SI_LABELS: dict[str, tuple[str, str | None]] = {
    "dissipated_energy": ("dissipated_energy_j", "energy"),
    "drive_energy": ("drive_energy_j", "energy"),
    "damping_energy": ("damping_energy_j", "energy"),
    "amplitude": ("amplitude_m", "length"),
    "mean_deflection": ("mean_deflection_m", "length"),
    "min_gap": ("min_gap_m", "length"),
    "max_force": ("max_force_n", "force"),
    "min_force": ("min_force_n", "force"),
    "phase": ("phase_rad", None),
}


def labels_to_si(labels: dict[str, Any], scales: Scales) -> dict[str, Any]:
    """Labels of :func:`trace_labels` (scalars, or arrays / lists per sweep row) in SI units.

    Dimensioned labels are renamed with their unit suffix (``amplitude`` -> ``amplitude_m``);
    dimensionless numbers and strings pass through unchanged. Scalars stay Python floats.
    """
    out: dict[str, Any] = {}
    for key, value in labels.items():
        name, unit = SI_LABELS.get(key, (key, None))
        if isinstance(value, str | list):
            out[name] = value
            continue
        v = np.asarray(value, dtype=float) * (getattr(scales, unit) if unit else 1.0)
        out[name] = float(v) if v.ndim == 0 else v
    return out
