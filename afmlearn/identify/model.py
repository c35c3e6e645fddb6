"""`IdentifiedModel`: an identified equation of motion, its force, its JSON form, its simulation.

    x'' + D x' + K x = -F_ts(z, z', x) + B cos(Omega tau - phi),   z = gap - x

with ``F_ts = sum_j c_j theta_j`` (``F_ts > 0`` repulsive), everything dimensionless (lengths /
``L_ref``, time ``tau = omega0 t``, force / ``(k L_ref)``); ``scales`` converts to SI.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io import jsonable, write_json
from simulator import Scales

from ._simulate import simulate_rk4
from .library import AFMLibrary, TermInput
from .library._kernel import force_series

__all__ = ["IdentifiedModel", "MODEL_FORMAT"]

FloatArray = NDArray[np.float64]
MODEL_FORMAT = "afmlearn-identified-model"


@final
@dataclass(frozen=True, eq=False)
class IdentifiedModel:
    """An identified single-mode model (dimensionless; see the module docstring).

    Parameters
    ----------
    library : AFMLibrary
        The force terms with nonzero coefficients (the selected support).
    coefficients : ndarray, shape (n_terms,)
        ``c_j`` of ``F_ts = sum_j c_j theta_j``, units ``k L_ref``.
    stiffness, damping : float
        ``K`` and ``D`` of the lever.
    drive_amplitude, drive_phase : float
        ``B`` (units ``k L_ref``) and ``phi`` [rad] of ``B cos(Omega tau - phi)``, ``tau`` from
        the first sample of the trace.
    omega : float
        Drive frequency / f0.
    a0 : float
        Contact onset / ``L_ref``.
    gap : float
        Rest gap / ``L_ref``.
    scales : simulator.Scales
        ``k`` [N/m], ``f0`` [Hz], ``L_ref`` [m].
    coefficient_bands : ndarray, shape (2, n_terms), optional
        2.5 % and 97.5 % quantiles of the coefficients from constrained bagging.
    info : dict
        Free metadata (selection settings, scores).
    """

    library: AFMLibrary
    coefficients: FloatArray
    stiffness: float
    damping: float
    drive_amplitude: float
    drive_phase: float
    omega: float
    a0: float
    gap: float
    scales: Scales
    coefficient_bands: FloatArray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        c = np.asarray(self.coefficients, float).reshape(-1)
        if c.size != self.library.n_terms:
            raise ValueError(f"coefficients must have {self.library.n_terms} entries "
                             f"(one per library term), got {c.size}")
        object.__setattr__(self, "coefficients", c)
        if self.coefficient_bands is not None:
            b = np.asarray(self.coefficient_bands, float)
            if b.shape != (2, c.size):
                raise ValueError(f"coefficient_bands must have shape (2, {c.size}), got {b.shape}")
            object.__setattr__(self, "coefficient_bands", b)

    # -- the force ------------------------------------------------------------------------
    def force(self, z: FloatArray, zdot: FloatArray, x: FloatArray | None = None) -> FloatArray:
        """``F_ts`` [k L_ref] at gaps ``z`` and rates ``z'`` (shape (n,)), compiled kernel."""
        z = np.ascontiguousarray(z, float)
        zdot = np.ascontiguousarray(zdot, float)
        x = self.gap - z if x is None else np.ascontiguousarray(x, float)
        kinds, p1, p2 = self.library.encode()
        return force_series(kinds, p1, p2, self.coefficients, self.a0, z, zdot, x)

    def force_reference(self, z: FloatArray, zdot: FloatArray,
                        x: FloatArray | None = None) -> FloatArray:
        """Same as :meth:`force` with the NumPy term implementations (the reference)."""
        x = self.gap - np.asarray(z) if x is None else np.asarray(x)
        s = TermInput(z=np.asarray(z, float), zdot=np.asarray(zdot, float), x=x, a0=self.a0)
        return self.library.evaluate(s) @ self.coefficients

    def force_si(self, z_m: FloatArray, zdot_m_per_s: FloatArray) -> FloatArray:
        """``F_ts`` [N] at gaps [m] and gap rates [m/s]."""
        sc = self.scales
        z = np.asarray(z_m) / sc.length
        zd = np.asarray(zdot_m_per_s) / (sc.length * sc.omega0)
        return self.force(z, zd) * sc.force

    # -- simulation -----------------------------------------------------------------------
    def simulate(self, x0: float, v0: float, *, tau0: float, dtau: float, n_samples: int,
                 substeps: int = 4) -> tuple[FloatArray, FloatArray]:
        """Deflection and velocity / L_ref from ``(x0, v0)`` at ``tau0``, shape (n_samples,)."""
        if n_samples < 1:
            raise ValueError(f"n_samples must be >= 1, got {n_samples}")
        if substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        kinds, p1, p2 = self.library.encode()
        return simulate_rk4(float(x0), float(v0), float(tau0), float(dtau), int(n_samples),
                            int(substeps), float(self.gap), float(self.stiffness),
                            float(self.damping), float(self.drive_amplitude),
                            float(self.drive_phase), float(self.omega), kinds, p1, p2,
                            self.coefficients, float(self.a0))

    # -- equations ------------------------------------------------------------------------
    def equation(self, *, precision: int = 4) -> str:
        """Dimensionless equation of motion, e.g. ``x'' + 0.00226 x' + 1 x = -F_ts + ...``."""
        p = precision
        terms = " ".join(f"{'+' if c >= 0 else '-'} {abs(c):.{p}g} {n}"
                         for c, n in zip(self.coefficients, self.library.names, strict=True))
        ph = self.drive_phase
        return (f"x'' + {self.damping:.{p}g} x' + {self.stiffness:.{p}g} x = -F_ts + "
                f"{self.drive_amplitude:.{p}g} cos({self.omega:.{p}g} tau "
                f"{'-' if ph >= 0 else '+'} {abs(ph):.{p}g});  F_ts = "
                f"{terms.lstrip('+ ') or '0'};  z = "
                f"{self.gap:.{p}g} - x, a0 = {self.a0:.{p}g}")

    def si_terms(self) -> list[dict[str, Any]]:
        """Each force term in SI: coefficient [N / m^(powers)] with its unit string."""
        sc = self.scales
        L, w0, F = sc.length, sc.omega0, sc.force
        out = []
        for c, t in zip(self.coefficients, self.library.terms, strict=True):
            length_pow, rate_pow = _dimensions(t)
            # theta_SI = theta * L^length_pow * (L w0)^rate_pow  ->  c_SI = c F / (...)
            scale = F / (L ** length_pow * (L * w0) ** rate_pow)
            unit = "N" + _unit(length_pow, rate_pow)
            out.append({"term": t.name, "coefficient": float(c * scale), "unit": unit})
        return out

    def equation_si(self, *, precision: int = 4) -> str:
        """Tip--sample force in SI, e.g. ``F_ts [N] = 1.2e-09 z^-2 + 4.5e+03 delta^1.5``."""
        p = precision
        parts = [f"{'+' if d['coefficient'] >= 0 else '-'} {abs(d['coefficient']):.{p}g} "
                 f"[{d['unit']}] {d['term']}" for d in self.si_terms()]
        sc = self.scales
        return (f"F_ts [N] = {' '.join(parts).lstrip('+ ') or '0'};  z [m] = gap - x, a0 = "
                f"{self.a0 * sc.length:.{p}g} m, gap = {self.gap * sc.length:.{p}g} m; "
                f"m x_tt + c x_t + k x = -F_ts + F0 cos(w t - phi) with k = "
                f"{sc.spring_constant * self.stiffness:.{p}g} N/m, Q = "
                f"{1.0 / self.damping:.{p}g}, F0 = {self.drive_amplitude * sc.force:.{p}g} N")

    # -- JSON -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        sc = self.scales
        return {
            "format": MODEL_FORMAT, "format_version": 1,
            "library": self.library.to_list(),
            "coefficients": self.coefficients.tolist(),
            "coefficient_bands": (None if self.coefficient_bands is None
                                  else self.coefficient_bands.tolist()),
            "stiffness": self.stiffness, "damping": self.damping,
            "drive_amplitude": self.drive_amplitude, "drive_phase": self.drive_phase,
            "omega": self.omega, "a0": self.a0, "gap": self.gap,
            "scales": {"spring_constant": sc.spring_constant,
                       "resonance_frequency": sc.resonance_frequency, "length": sc.length},
            "equation": self.equation(), "equation_si": self.equation_si(),
            "si_terms": self.si_terms(),
            "info": jsonable(self.info),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> IdentifiedModel:
        if d.get("format") != MODEL_FORMAT:
            raise ValueError(f"not an identified model (format {d.get('format')!r}, "
                             f"expected {MODEL_FORMAT!r})")
        bands = d.get("coefficient_bands")
        return cls(library=AFMLibrary.from_list(d["library"]),
                   coefficients=np.asarray(d["coefficients"], float),
                   stiffness=float(d["stiffness"]), damping=float(d["damping"]),
                   drive_amplitude=float(d["drive_amplitude"]),
                   drive_phase=float(d["drive_phase"]), omega=float(d["omega"]),
                   a0=float(d["a0"]), gap=float(d["gap"]), scales=Scales(**d["scales"]),
                   coefficient_bands=None if bands is None else np.asarray(bands, float),
                   info=dict(d.get("info", {})))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the JSON atomically; returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> IdentifiedModel:
        return cls.from_dict(json.loads(Path(path).read_text()))


def _dimensions(term: Any) -> tuple[float, float]:
    """(length power, rate power) of a term's value: theta_SI = theta L^a (L w0)^b."""
    from .library import (
        Constant,
        ContactIndicator,
        DeflectionPower,
        ExponentialDamping,
        GapRate,
        Indentation,
        IndentationRate,
        InversePower,
        SphereElectrostatic,
    )
    if isinstance(term, Constant | ContactIndicator | ExponentialDamping):
        return (0.0, 1.0) if isinstance(term, ExponentialDamping) else (0.0, 0.0)
    if isinstance(term, DeflectionPower):
        return float(term.power), 0.0
    if isinstance(term, InversePower):
        return -float(term.n), 0.0
    if isinstance(term, SphereElectrostatic):
        return -2.0, 0.0
    if isinstance(term, Indentation):
        return float(term.p), 0.0
    if isinstance(term, IndentationRate | GapRate):
        return float(term.p), float(term.l)
    raise ValueError(f"no SI dimensions for {term!r}")


def _unit(length_pow: float, rate_pow: float) -> str:
    parts = []
    if length_pow:
        parts.append(f"m^{-length_pow:g}")
    if rate_pow:
        parts.append(f"(m/s)^{-rate_pow:g}")
    return " " + " ".join(parts) if parts else ""
