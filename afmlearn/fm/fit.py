"""One joint fit of Δf(z, V) over all piezo positions and biases: :class:`FMFit`.

Variable projection: for given nonlinear parameters (contact position ``z_contact``, tip radius
``R``, ``V_cpd``) the frequency shift is linear in the van der Waals and contact coefficients,
the far-field gradient and the Δf offset, solved by bounded linear least squares
(``scipy.optimize.lsq_linear``); the outer problem is ``scipy.optimize.least_squares`` from a
few starts. The residual is in Hz, unweighted. Lengths inside are in units of the oscillation
amplitude ``A`` (so the quadrature is over a unit amplitude), forces in ``k A``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, lsq_linear

from afmlearn.fm.forward import law_frequency_shift
from afmlearn.fm.model import A0_M, FMLaw
from afmlearn.io.instruments.fm_table import FMSpectroscopy
from simulator.forces.law import ForceLaw, Kind, Term

__all__ = ["FMFit", "model_hz"]

log = logging.getLogger(__name__)
_CHI2_95 = 3.841458820694124  # 95 % quantile of chi2 with 1 degree of freedom


def _bases(spec: FMSpectroscopy, law: FMLaw, n_nodes: int
           ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``Omega`` per unit coefficient of the vdW and contact terms of ``law``'s shape (radius,
    contact position) and the electrostatic ``Omega`` per V**2 (prefactor ``pi eps0 R_e**2``
    included), each shape (n_z,)."""
    ell, k = spec.amplitude_m, spec.spring_constant_n_per_m
    d = (spec.z_piezo_m - law.z_contact_m) / ell
    r = law.tip_radius_m / ell
    a0 = A0_M / ell
    out = []
    for term in (Term(Kind.SPHERE_VDW, -1.0, r), Term(Kind.INDENTATION, 1.0, 1.5)):
        out.append(law_frequency_shift(ForceLaw((term,), a0=a0, has_contact=True), d,
                                       amplitude=1.0, n_nodes=n_nodes))
    unit = replace(law, vcpd_v=0.0, electrostatic=True)
    es = unit.electrostatic_law(1.0, length_m=ell, spring_constant_n_per_m=k)
    out.append(law_frequency_shift(es, d + law.es_setback_m / ell, amplitude=1.0,
                                   n_nodes=n_nodes))
    return out[0], out[1], out[2]


def model_hz(spec: FMSpectroscopy, law: FMLaw, *, n_nodes: int = 64) -> NDArray[np.float64]:
    """Δf [Hz] of ``law`` at the map's positions and biases, shape (n_z, n_bias)."""
    ell, k, f0 = spec.amplitude_m, spec.spring_constant_n_per_m, spec.resonance_frequency_hz
    b_vdw, b_rep, b_es = _bases(spec, law, n_nodes)
    r = law.tip_radius_m / ell
    c_vdw = 2.0 * law.hamaker_j * r**3 / (3.0 * k * ell**2)
    c_rep = 4.0 / 3.0 * law.modulus_pa * math.sqrt(law.tip_radius_m * ell) / k
    out = f0 * (c_vdw * b_vdw + c_rep * b_rep)[:, None] + law.offset_hz
    if law.electrostatic:
        v2 = (spec.bias_v - law.vcpd_v) ** 2
        g = law.far_gradient_n_per_m_v2 / k
        out = (out + f0 * b_es[:, None] * v2[None, :]
               - 0.5 * f0 * g * (spec.bias_v - law.far_v)[None, :] ** 2)
    return np.broadcast_to(out, spec.shape).copy()


@final
@dataclass
class _Linear:
    """The inner solution: the law with its linear coefficients and the residual [Hz],
    shape (n_z * n_bias,)."""

    law: FMLaw
    residual: NDArray[np.float64]


@final
class FMFit:
    """Least-squares fit of one :class:`FMLaw` to a whole Δf(z, V) map.

    Parameters
    ----------
    electrostatic : bool
        False: the baseline law without bias-dependent terms.
    vcpd_v : float or None
        Fix ``V_cpd`` [V] (e.g. 0 for the "no CPD" baseline); None: fitted.
    far_cpd : bool
        True: the far-field term has its own potential ``V_far`` (fitted); False: ``V_cpd``.
    shared_radius : bool
        True: the electrostatic sphere is the contact's sphere (``R_e = R``, ``s_e = 0``),
        the textbook model; False: ``R_e`` and ``s_e`` fitted.
    radius_starts_m : tuple of float
        Starting radii [m] of the outer fit.
    contact_window_m : tuple of float
        The contact position is searched in ``[z_min - w0, z_min + w1]`` [m] (``z_min`` the
        closest piezo position of the fitted map).
    contact_bounds_m : tuple of float or None
        Absolute bounds [m] of the contact position instead (e.g. when the closest rows of a
        map are left out of the fit).
    n_nodes : int
        Quadrature nodes of the Δf integral.

    Attributes
    ----------
    law_ : FMLaw
        The fitted law.
    rss_hz2_ : float
        Residual sum of squares [Hz**2].
    n_obs_, n_params_ : int
        Number of fitted Δf values and of free parameters.
    rms_hz_ : float
        Root-mean-square residual [Hz].
    """

    def __init__(self, *, electrostatic: bool = True, vcpd_v: float | None = None,
                 far_cpd: bool = True, shared_radius: bool = False,
                 radius_starts_m: tuple[float, ...] = (3e-9, 30e-9),
                 contact_window_m: tuple[float, float] = (2e-9, 3e-9),
                 contact_bounds_m: tuple[float, float] | None = None,
                 n_nodes: int = 64) -> None:
        self.electrostatic = electrostatic
        self.vcpd_v = vcpd_v
        self.far_cpd = far_cpd
        self.shared_radius = shared_radius
        self.radius_starts_m = radius_starts_m
        self.contact_window_m = contact_window_m
        self.contact_bounds_m = contact_bounds_m
        self.n_nodes = n_nodes

    # -- outer parameters ----------------------------------------------------------------
    def _free(self, vcpd_fixed: float | None) -> list[str]:
        names = ["z_contact_nm", "log_radius_nm"]
        if self.electrostatic:
            if not self.shared_radius:
                names += ["log_es_radius_nm", "es_setback_nm"]
            if vcpd_fixed is None:
                names.append("vcpd_v")
        return names

    def _shape(self, values: dict[str, float], vcpd_fixed: float | None) -> FMLaw:
        """The law's nonlinear shape (coefficients 0) from outer values."""
        radius = math.exp(values["log_radius_nm"]) * 1e-9
        shared = self.shared_radius or not self.electrostatic
        return FMLaw(hamaker_j=0.0, modulus_pa=0.0, tip_radius_m=radius,
                     vcpd_v=(vcpd_fixed if vcpd_fixed is not None else values.get("vcpd_v", 0.0))
                     if self.electrostatic else 0.0,
                     es_radius_m=radius if shared else math.exp(values["log_es_radius_nm"]) * 1e-9,
                     es_setback_m=0.0 if shared else values["es_setback_nm"] * 1e-9,
                     z_contact_m=values["z_contact_nm"] * 1e-9, electrostatic=self.electrostatic)

    def _contact_range_nm(self, spec: FMSpectroscopy) -> tuple[float, float]:
        if self.contact_bounds_m is not None:
            lo, hi = sorted(self.contact_bounds_m)
            return lo * 1e9, hi * 1e9
        z_min = float(np.min(spec.z_piezo_m)) * 1e9
        return z_min - self.contact_window_m[0] * 1e9, z_min + self.contact_window_m[1] * 1e9

    def _bounds(self, spec: FMSpectroscopy, names: list[str]) -> tuple[list[float], list[float]]:
        table = {"z_contact_nm": self._contact_range_nm(spec),
                 "log_radius_nm": (math.log(0.3), math.log(1000.0)),
                 "log_es_radius_nm": (math.log(0.3), math.log(3000.0)),
                 "es_setback_nm": (0.0, 50.0),
                 "vcpd_v": (float(np.min(spec.bias_v)), float(np.max(spec.bias_v)))}
        return [table[n][0] for n in names], [table[n][1] for n in names]

    # -- inner linear problem ------------------------------------------------------------
    def _linear(self, spec: FMSpectroscopy, shape: FMLaw) -> _Linear:
        ell, k, f0 = spec.amplitude_m, spec.spring_constant_n_per_m, spec.resonance_frequency_hz
        b_vdw, b_rep, b_es = _bases(spec, shape, self.n_nodes)
        n_z, n_v = spec.shape
        data = spec.frequency_shift_hz
        cols = [np.repeat(f0 * b_vdw, n_v), np.repeat(f0 * b_rep, n_v)]
        lower, upper = [0.0, 0.0], [np.inf, np.inf]
        target = data
        if self.electrostatic:
            v2 = (spec.bias_v - shape.vcpd_v) ** 2
            target = data - f0 * b_es[:, None] * v2[None, :]
            if self.far_cpd:  # g (V - V_far)**2 = g V**2 - 2 h V + const, h = g V_far
                v = spec.bias_v
                cols += [np.tile(-0.5 * f0 * v**2, n_z), np.tile(f0 * v, n_z)]
                lower += [0.0, -np.inf]
                upper += [np.inf, np.inf]
            else:
                cols.append(np.tile(-0.5 * f0 * v2, n_z))
                lower.append(0.0)
                upper.append(np.inf)
        cols.append(np.ones(n_z * n_v))
        lower.append(-np.inf)
        upper.append(np.inf)
        a = np.column_stack(cols)
        scale = np.linalg.norm(a, axis=0)
        scale[scale == 0] = 1.0
        sol = lsq_linear(a / scale, target.ravel(), bounds=(lower, upper), method="bvls")
        coef = sol.x / scale
        r = shape.tip_radius_m / ell
        offset, g, v_far = coef[-1], (coef[2] if self.electrostatic else 0.0), None
        if self.electrostatic and self.far_cpd:
            v_far = coef[3] / g if g > 1e-300 else shape.vcpd_v
            offset += 0.5 * f0 * g * v_far**2
        law = replace(shape, hamaker_j=coef[0] * 3.0 * k * ell**2 / (2.0 * r**3),
                      modulus_pa=coef[1] * k * 3.0 / (4.0 * math.sqrt(shape.tip_radius_m * ell)),
                      far_gradient_n_per_m_v2=g * k, far_vcpd_v=v_far, offset_hz=offset)
        return _Linear(law, a @ coef - target.ravel())

    def _solve(self, spec: FMSpectroscopy, vcpd_fixed: float | None,
               starts: list[dict[str, float]]) -> _Linear:
        names = self._free(vcpd_fixed)
        lo, hi = self._bounds(spec, names)

        def law_of(x: NDArray[np.float64]) -> FMLaw:
            return self._shape(dict(zip(names, x, strict=True)), vcpd_fixed)

        def residual(x: NDArray[np.float64]) -> NDArray[np.float64]:
            return self._linear(spec, law_of(x)).residual

        scored = []
        for start in starts:
            x0 = np.clip([start[n] for n in names], np.add(lo, 1e-6), np.subtract(hi, 1e-6))
            scored.append((float(np.sum(residual(x0) ** 2)), x0))
        scored.sort(key=lambda t: t[0])
        best = None
        for _, x0 in scored[:3]:
            sol = least_squares(residual, x0, bounds=(lo, hi), x_scale="jac", diff_step=1e-4,
                                max_nfev=300)
            if best is None or sol.cost < best.cost:
                best = sol
        assert best is not None
        return self._linear(spec, law_of(best.x))

    def _starts(self, spec: FMSpectroscopy, vcpd: float) -> list[dict[str, float]]:
        lo, hi = self._contact_range_nm(spec)
        zs = np.linspace(lo, hi, max(3, int((hi - lo) / 0.75) + 1))[1:-1]
        return [{"z_contact_nm": z, "log_radius_nm": math.log(r * 1e9),
                 "log_es_radius_nm": math.log(re), "es_setback_nm": se, "vcpd_v": vcpd}
                for z in zs for r in self.radius_starts_m for re in (10.0, 50.0)
                for se in (0.5, 3.0)]

    def fit(self, spec: FMSpectroscopy, *, initial: FMLaw | None = None) -> FMFit:
        """Fit ``spec`` (all positions, all bias columns; one start at ``initial`` if given,
        else a grid of starts); returns self."""
        if spec.shape[1] < 4 and self.electrostatic and self.vcpd_v is None:
            raise ValueError("spec: a V_cpd fit needs >= 4 bias columns")
        from afmlearn.fm.kelvin import kelvin_parabolas

        v0 = self.vcpd_v if self.vcpd_v is not None else (
            float(np.nanmedian(kelvin_parabolas(spec)["vcpd_v"])) if self.electrostatic
            else 0.0)
        starts = self._starts(spec, v0) if initial is None else [_values(initial)]
        lin = self._solve(spec, self.vcpd_v, starts)
        self.law_ = lin.law
        self.rss_hz2_ = float(np.sum(lin.residual**2))
        self.n_obs_ = int(lin.residual.size)
        self.n_params_ = len(self._free(self.vcpd_v)) + 3 + (
            (1 + self.far_cpd) if self.electrostatic else 0)
        self.rms_hz_ = math.sqrt(self.rss_hz2_ / self.n_obs_)
        log.info("FM fit: rms %.3g Hz, %s", self.rms_hz_, self.law_)
        return self

    def predict_hz(self, spec: FMSpectroscopy) -> NDArray[np.float64]:
        """Δf [Hz] of the fitted law at ``spec``'s positions and biases, (n_z, n_bias)."""
        return model_hz(spec, self.law_, n_nodes=self.n_nodes)

    def profile_vcpd(self, spec: FMSpectroscopy, *, half_width_v: float = 0.3,
                     n_points: int = 13) -> dict[str, Any]:
        """Profile likelihood of ``V_cpd`` (the other parameters refitted on a grid).

        Gaussian residuals with the fit's own variance ``rss / (n - p)``: the interval is
        where ``(rss(V) - rss_min) / sigma**2 <= 3.84`` (95 %). Correlated residuals (model
        error, drift) make it too narrow: see the per-z parabolas for the spread.

        Returns
        -------
        dict
            ``grid_v`` (n_points,), ``delta_chi2`` (n_points,), ``low_v``, ``high_v`` (None
            when the grid does not bound it), ``sigma_hz``.
        """
        if not (self.electrostatic and self.vcpd_v is None):
            raise ValueError("profile_vcpd: needs a fit with a free V_cpd")
        best = self.law_
        sigma2 = self.rss_hz2_ / (self.n_obs_ - self.n_params_)
        grid = best.vcpd_v + np.linspace(-half_width_v, half_width_v, n_points)
        start = _values(best)
        rss = np.array([float(np.sum(self._solve(spec, float(v), [start]).residual ** 2))
                        for v in grid])
        rss_min = min(self.rss_hz2_, float(rss.min()))
        dchi = (rss - rss_min) / sigma2
        return {"grid_v": grid.tolist(), "delta_chi2": dchi.tolist(),
                "low_v": _crossing(grid, dchi, side=-1, at=best.vcpd_v),
                "high_v": _crossing(grid, dchi, side=+1, at=best.vcpd_v),
                "sigma_hz": math.sqrt(sigma2)}


def _values(law: FMLaw) -> dict[str, float]:
    """Outer-parameter values of ``law`` (a start of the outer fit)."""
    return {"z_contact_nm": law.z_contact_m * 1e9,
            "log_radius_nm": math.log(law.tip_radius_m * 1e9),
            "log_es_radius_nm": math.log(law.es_radius_m * 1e9),
            "es_setback_nm": law.es_setback_m * 1e9, "vcpd_v": law.vcpd_v}


def _crossing(grid: NDArray[np.float64], dchi: NDArray[np.float64], *, side: int, at: float
              ) -> float | None:
    """Where ``dchi`` crosses the 95 % level on one side of ``at`` (linear interpolation)."""
    idx = np.flatnonzero(grid < at) if side < 0 else np.flatnonzero(grid > at)
    if idx.size == 0:
        return None
    order = idx[::-1] if side < 0 else idx
    prev_v, prev_c = at, 0.0
    for i in order:
        if dchi[i] >= _CHI2_95:
            t = (_CHI2_95 - prev_c) / (dchi[i] - prev_c) if dchi[i] != prev_c else 0.0
            return float(prev_v + t * (grid[i] - prev_v))
        prev_v, prev_c = float(grid[i]), float(dchi[i])
    return None
