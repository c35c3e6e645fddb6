"""Cantilever with 1--3 flexural modes (dimensionless modal equations, ``physics.md`` §2).

Mode ``i`` obeys ``q_i'' + D_i(regime) q_i' + K_i q_i = drive_i - s_i F_ts``; the tip deflection
(towards the sample) is ``x = sum_i q_i``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import final

import numpy as np
from numpy.typing import NDArray

__all__ = ["Cantilever", "RECTANGULAR_FREQUENCY_RATIOS", "RECTANGULAR_BASE_PARTICIPATION"]

#: omega_i / omega_1 of a clamped--free Euler--Bernoulli beam
RECTANGULAR_FREQUENCY_RATIOS = (1.0, 6.267, 17.55)
#: base-excitation participation factors of the same beam (tip-normalised modes)
RECTANGULAR_BASE_PARTICIPATION = (1.566, -0.868, 0.509)


def _vector(name: str, values: Sequence[float] | NDArray, n: int, *, low: float,
            low_open: bool = False) -> NDArray[np.float64]:
    a = np.asarray(values, dtype=float).reshape(-1)
    if a.shape != (n,):
        raise ValueError(f"{name} must have one value per mode ({n}), got shape {a.shape}")
    bad = ~np.isfinite(a) | ((a <= low) if low_open else (a < low))
    if bad.any():
        op = ">" if low_open else ">="
        raise ValueError(f"{name} must be finite and {op} {low:g} for every mode, got {a.tolist()}")
    return a


@final
@dataclass(frozen=True, eq=False)
class Cantilever:
    """Modal parameters of a cantilever (dimensionless).

    Parameters
    ----------
    stiffness : sequence of float, shape (n_modes,)
        ``K_i = (omega_i / omega_1)**2``; ``K_1`` must be 1 and ``K`` increasing.
    damping : sequence of float, shape (n_modes,)
        ``D_i`` out of contact (``sqrt(K_i) / Q_i``), >= 0.
    contact_damping : sequence of float, shape (n_modes,), optional
        ``D_i`` while in contact (piecewise modal damping); defaults to ``damping``.
    base_participation : sequence of float, shape (n_modes,), optional
        ``B_i`` for base excitation; defaults to the rectangular-beam values.
    force_gain : sequence of float, shape (n_modes,), optional
        ``s_i``: share of the tip force acting on mode ``i`` (1 for tip-normalised modes of
        equal modal mass, the default); tip drive forces use the same gains.
    """

    stiffness: Sequence[float] | NDArray
    damping: Sequence[float] | NDArray
    contact_damping: Sequence[float] | NDArray | None = None
    base_participation: Sequence[float] | NDArray | None = None
    force_gain: Sequence[float] | NDArray | None = None
    n_modes: int = field(init=False)

    def __post_init__(self) -> None:
        k = np.asarray(self.stiffness, dtype=float).reshape(-1)
        n = k.size
        if not 1 <= n <= 3:
            raise ValueError(f"stiffness: 1 to 3 modes are supported, got {n}")
        k = _vector("stiffness", k, n, low=0.0, low_open=True)
        if abs(k[0] - 1.0) > 1e-12:
            raise ValueError(f"stiffness: K_1 must be 1 (normalised fundamental), got {k[0]}")
        if np.any(np.diff(k) <= 0):
            raise ValueError(f"stiffness: K_i must increase with the mode number, got {k.tolist()}")
        d = _vector("damping", self.damping, n, low=0.0)
        dc = d if self.contact_damping is None else _vector(
            "contact_damping", self.contact_damping, n, low=0.0)
        b = (np.asarray(RECTANGULAR_BASE_PARTICIPATION[:n]) if self.base_participation is None
             else np.asarray(self.base_participation, dtype=float).reshape(-1))
        if b.shape != (n,) or not np.all(np.isfinite(b)):
            raise ValueError(f"base_participation must hold {n} finite values, got {b.tolist()}")
        s = np.ones(n) if self.force_gain is None else _vector(
            "force_gain", self.force_gain, n, low=0.0, low_open=True)
        for name, val in (("stiffness", k), ("damping", d), ("contact_damping", dc),
                          ("base_participation", b), ("force_gain", s)):
            val = np.array(val, dtype=float)
            val.setflags(write=False)
            object.__setattr__(self, name, val)
        object.__setattr__(self, "n_modes", n)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def rectangular(
        cls,
        *,
        n_modes: int = 1,
        quality_factor: float,
        higher_quality_factors: Sequence[float] | None = None,
        contact_quality_factors: Sequence[float] | None = None,
        frequency_ratios: Sequence[float] | None = None,
        base_participation: Sequence[float] | None = None,
    ) -> Cantilever:
        """Rectangular beam: ``omega_i/omega_1 = 1, 6.267, 17.55`` and ``B = 1.566, -0.868, .509``.

        Parameters
        ----------
        n_modes : int
            1, 2 or 3.
        quality_factor : float
            ``Q_1`` in air, > 0.
        higher_quality_factors : sequence of float, optional
            ``Q_2, Q_3``; default ``Q_1 sqrt(omega_i / omega_1)``, between a viscous-drag
            (``Q ~ omega``) and a structural-loss (``Q`` constant) scaling.
        contact_quality_factors : sequence of float, shape (n_modes,), optional
            Quality factors in contact; default: same as in air.
        frequency_ratios : sequence of float, optional
            ``omega_i / omega_1`` overriding the beam values (e.g. ``[1, 6]`` for 6:1).
        base_participation : sequence of float, optional
            Overrides ``B_i``.
        """
        if n_modes not in (1, 2, 3):
            raise ValueError(f"n_modes must be 1, 2 or 3, got {n_modes!r}")
        if not (np.isfinite(quality_factor) and quality_factor > 0):
            raise ValueError(f"quality_factor must be > 0, got {quality_factor!r}")
        ratios = np.asarray(frequency_ratios if frequency_ratios is not None
                            else RECTANGULAR_FREQUENCY_RATIOS[:n_modes], dtype=float)
        if ratios.shape != (n_modes,):
            raise ValueError(f"frequency_ratios must hold {n_modes} values, got {ratios.tolist()}")
        q = np.empty(n_modes)
        q[0] = quality_factor
        if n_modes > 1:
            q[1:] = (quality_factor * np.sqrt(ratios[1:]) if higher_quality_factors is None
                     else np.asarray(higher_quality_factors, dtype=float)[: n_modes - 1])
        q = _vector("quality factors", q, n_modes, low=0.0, low_open=True)
        qc = q if contact_quality_factors is None else _vector(
            "contact_quality_factors", contact_quality_factors, n_modes, low=0.0, low_open=True)
        return cls(
            stiffness=ratios**2,
            damping=ratios / q,
            contact_damping=ratios / qc,
            base_participation=(None if base_participation is None
                                else np.asarray(base_participation, dtype=float)[:n_modes]),
        )

    # ------------------------------------------------------------------ properties
    @property
    def frequency_ratios(self) -> NDArray[np.float64]:
        """``omega_i / omega_1``, shape (n_modes,)."""
        return np.sqrt(self.stiffness)

    @property
    def quality_factors(self) -> NDArray[np.float64]:
        """Quality factors in air ``sqrt(K_i) / D_i``, shape (n_modes,)."""
        with np.errstate(divide="ignore"):
            return np.sqrt(self.stiffness) / self.damping

    def receptance(self, omega: float) -> NDArray[np.complex128]:
        """Complex modal receptance ``1 / (K_i - Omega**2 + i D_i Omega)``, shape (n_modes,)."""
        return 1.0 / (self.stiffness - omega**2 + 1j * self.damping * omega)

    def to_dict(self) -> dict[str, list[float]]:
        """JSON-serialisable parameters."""
        return {k: np.asarray(getattr(self, k)).tolist() for k in
                ("stiffness", "damping", "contact_damping", "base_participation", "force_gain")}
