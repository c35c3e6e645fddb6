"""Forward model of a lock-in curve: slow flow along the ramp, then the lock-in filter."""

from __future__ import annotations

import math
from typing import final

import numpy as np
from numpy.typing import NDArray

from simulator.lockin import LockIn

from . import _kernel
from .curve import Curve
from .law import CurveLaw

__all__ = ["SlowFlowModel", "drive_from_free"]


def drive_from_free(free_phase: float, quality_factor: float) -> tuple[float, float]:
    """Drive frequency ``W = omega / omega0`` and force ``B`` of a unit free amplitude.

    From the free steady state of the single-mode lever: ``tan(phi_f) = W / (Q (1 - W**2))``
    and ``B = sqrt((1 - W**2)**2 + (W / Q)**2)``.
    """
    q = float(quality_factor)
    t = math.cos(free_phase) / max(math.sin(free_phase), 1e-12)  # cot(phi_f)
    # Q (1 - W^2) cot... : Q cot(phi) W... solve W/(Q(1-W^2)) = tan(phi) for W > 0
    if abs(t) < 1e-12:
        w = 1.0
    else:
        qt = q / t  # Q tan(phi)
        w = (-1.0 + math.sqrt(1.0 + 4.0 * qt * qt)) / (2.0 * qt) if qt > 0 else \
            (1.0 + math.sqrt(1.0 + 4.0 * qt * qt)) / (-2.0 * qt)
    b = math.sqrt((1.0 - w * w) ** 2 + (w / q) ** 2)
    return w, b


@final
class SlowFlowModel:
    """Amplitude and phase of a single-mode lever along a ramp, as a lock-in records them.

    Parameters
    ----------
    quality_factor : float
        Q of the free fundamental.
    omega : float
        Drive frequency / f0.
    drive : float
        Drive force ``B`` (units of the length scale: a unit free amplitude at resonance
        has ``B = 1/Q``).
    lockin : LockIn or None
        The lock-in's low-pass (its ``output_interval`` is not used: outputs are taken at the
        curve's times). None: no filter.
    step : float
        Grid of the slow flow and of the filter (dimensionless time, > 0).
    max_turn : float
        Largest phase turn / relative amplitude change per RK4 sub-step.
    settle : float
        Time integrated at the first gap before the first sample, in units of ``2Q``.
    tolerance : float or None
        Local error per step of the adaptive Dormand--Prince integration
        (:func:`_kernel.integrate_adaptive`; absolute, on amplitude / free amplitude and lag
        [rad]). None: the fixed-grid RK4 reference (:func:`_kernel.integrate`, sub-stepped by
        ``max_turn``), several times slower on a long ramp.
    max_step : float
        Longest adaptive step (dimensionless time), in units of ``2Q`` (the lever's amplitude
        time constant).
    min_step : float
        Shortest adaptive step, in units of ``step``: accepted whatever its error (bounds the
        cost where the averaged rates jump, at the adhesion neck's switch).

    Attributes
    ----------
    n_steps_ : int
        Integration steps of the last :meth:`predict` (adaptive only; 0 for the reference).
    """

    def __init__(self, *, quality_factor: float, omega: float, drive: float,
                 lockin: LockIn | None = None, step: float = 2.0 * math.pi,
                 max_turn: float = 0.25, settle: float = 3.0,
                 tolerance: float | None = 1e-7, max_step: float = 2.0,
                 min_step: float = 1.0 / 16.0) -> None:
        for name, v in (("quality_factor", quality_factor), ("omega", omega),
                        ("drive", drive), ("step", step), ("max_turn", max_turn),
                        ("max_step", max_step), ("min_step", min_step),
                        ("tolerance", 1.0 if tolerance is None else tolerance)):
            if not (math.isfinite(float(v)) and float(v) > 0.0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        self.quality_factor = float(quality_factor)
        self.omega = float(omega)
        self.drive = float(drive)
        self.lockin = lockin
        self.step = float(step)
        self.max_turn = float(max_turn)
        self.settle = float(settle)
        self.tolerance = None if tolerance is None else float(tolerance)
        self.max_step = float(max_step)
        self.min_step = float(min_step)
        self.n_steps_ = 0

    @classmethod
    def for_curve(cls, curve: Curve, *, lockin: LockIn | None = None,
                  step: float = 2.0 * math.pi) -> SlowFlowModel:
        """Drive frequency and force from the curve's free phase and unit free amplitude."""
        w, b = drive_from_free(curve.free_phase, curve.quality_factor)
        return cls(quality_factor=curve.quality_factor, omega=w, drive=b, lockin=lockin,
                   step=step)

    def free_state(self) -> tuple[float, float]:
        """(amplitude, lag) of the free steady state."""
        w, q = self.omega, self.quality_factor
        amp = self.drive / math.hypot(1.0 - w * w, w / q)
        return amp, math.atan2(w / q, 1.0 - w * w)

    def predict(self, law: CurveLaw, tau: NDArray[np.float64], gap: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Amplitude and lag at times ``tau`` for the rest-gap programme ``gap``.

        Parameters
        ----------
        law : CurveLaw
        tau : ndarray, shape (m,)
            Increasing sample times (dimensionless).
        gap : ndarray, shape (m,)
            Rest gap at those times (linear in between).

        Returns
        -------
        amplitude, phase : ndarray, shape (m,)
        """
        h = self.step
        n_settle = int(math.ceil(self.settle * 2.0 * self.quality_factor / h))
        n = int(math.ceil((tau[-1] - tau[0]) / h)) + 1
        grid = tau[0] + h * np.arange(n)
        g = np.concatenate([np.full(n_settle, gap[0]), np.interp(grid, tau, gap)])
        a0, p0 = self.free_state()
        if self.tolerance is None:
            amp, phi = _kernel.integrate(law.vector(), g, h, a0, p0, self.quality_factor,
                                         self.omega, self.drive, _kernel._GL_X, _kernel._GL_W,
                                         self.max_turn)
        else:
            amp, phi, self.n_steps_ = _kernel.integrate_adaptive(
                law.vector(), g, h, a0, p0, self.quality_factor, self.omega, self.drive,
                _kernel._GL_X, _kernel._GL_W, self.tolerance,
                self.max_step * 2.0 * self.quality_factor, h * self.min_step)
        iq = np.stack([amp * np.cos(phi), amp * np.sin(phi)])
        if self.lockin is not None:
            iq = self.lockin.filter(iq, dt=h)
        iq = iq[:, n_settle:]
        i = np.interp(tau, grid, iq[0])
        q = np.interp(tau, grid, iq[1])
        return np.hypot(i, q), np.arctan2(q, i)
