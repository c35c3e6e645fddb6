"""The single-orbit identification problem: one record's training span bound to its rows.

One trace (or one row of a sweep, or a ramp) becomes ONE regression

    rows:  [x''] = -D [x'] - K [x] + B_c [cos] + B_s [sin] - sum_j c_j [theta_j]

on the training span (the periods before the held-out ones), projected by
:class:`~afmlearn.identify.projection.HarmonicBalance` (periodic data, Fourier-series state)
or :class:`~afmlearn.identify.weak.WeakForm` (otherwise, Savitzky--Golay state).

Everything here is immutable: :class:`OrbitProblem` is built once by
:func:`build_orbit_problem` (split, denoise, bind, threshold and ``a0`` grids, the held-out
reference); a drive rotation or a noise scale gives a NEW problem
(:meth:`OrbitProblem.with_drive`, :meth:`OrbitProblem.with_noise`); :meth:`OrbitProblem.design`
is a pure function of ``(library, a0)`` and returns the joint path's
:class:`~afmlearn.identify.problem.JointDesign` (rows, boxes and threshold pattern; the same
concept), so the stages of :mod:`afmlearn.identify.single` and the joint :class:`Bagging` read
the same interface (``design``, ``prior``, ``blocks``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.preprocess import (
    Calibrated,
    HarmonicFit,
    default_window,
    fit_harmonics,
    savgol_derivatives,
)

from .constraints import CalibrationConstraints
from .library import AFMLibrary, TermInput
from .optimizers import BoxSR3
from .problem import JointDesign
from .projection import AbstractProjection, Bound, Denoised, HarmonicBalance, RegressionData
from .stepwise import cv_errors
from .weak import WeakForm

__all__ = ["N_LIN", "OrbitProblem", "build_orbit_problem"]

FloatArray = NDArray[np.float64]

#: the four lever/drive columns ``[x', x, cos(Omega tau), sin(Omega tau)]``
N_LIN = 4


@final
@dataclass(frozen=True, eq=False)
class OrbitProblem:
    """One record's training span bound to its rows; immutable.

    Attributes
    ----------
    calibrated : Calibrated
        The whole record (training and held-out samples), dimensionless.
    constraints : CalibrationConstraints
    bound : Bound
        The projection's rows of the training span.
    denoised : Denoised
        State of the training span: ``x``, ``v`` shape (heldout_start,), with the Fourier
        series when periodic.
    periodic : bool
    projection : AbstractProjection
        The projection used (:class:`HarmonicBalance` or :class:`WeakForm`).
    heldout_start : int
        First held-out sample (the training span is ``[0, heldout_start)``).
    heldout_reference : tuple of 3 ndarray, each shape (n - heldout_start,)
        Denoised held-out ``x``, ``x'``, ``x''`` (never used in fitting).
    thresholds : ndarray, shape (n_t,)
        SR3 threshold grid (force units ``k L_ref`` of a term's RMS contribution).
    nus : ndarray, shape (n_nu,)
        SR3 relaxation grid.
    a0_grid : ndarray, shape (n_grid,)
        Contact onsets of the ``a0`` profile (/ L_ref); its span is the allowed ``a0`` range.
    orbit_span : float
        Gap span of the denoised orbit (/ L_ref): the scale of ``a0`` tolerances.
    physical_signs : bool
        Bound the force coefficients' signs (``AbstractTerm.sign``).
    rotation : float
        Drive phase ``phi`` [rad] the drive columns are rotated to (``cos(Omega tau - phi)``,
        ``sin(Omega tau - phi)``).
    drive_rotated : bool
        The in-phase drive is boxed (and has a prior) about ``F_c``: set once the drive phase
        is chosen, when ``F_c`` is calibrated.
    noise_variance : float or None
        Row noise variance from a dense fit (the priors' unit); None until a noise stage set
        it (:meth:`with_noise`).
    """

    calibrated: Calibrated
    constraints: CalibrationConstraints
    bound: Bound
    denoised: Denoised
    periodic: bool
    projection: AbstractProjection
    heldout_start: int
    heldout_reference: tuple[FloatArray, FloatArray, FloatArray]
    thresholds: FloatArray
    nus: FloatArray
    a0_grid: FloatArray
    orbit_span: float
    physical_signs: bool
    rotation: float = 0.0
    drive_rotated: bool = False
    noise_variance: float | None = None

    #: number of lever/drive columns before the force terms
    n_lin: ClassVar[int] = N_LIN

    # ------------------------------------------------------------------ views
    @property
    def blocks(self) -> list[tuple[int, int]]:
        """Row index ranges of the time-ordered blocks (rolling cross-validation)."""
        return self.bound.blocks

    @property
    def a0_range(self) -> tuple[float, float]:
        """Allowed contact onset ``(low, high)`` (/ L_ref): the span of :attr:`a0_grid`."""
        return float(self.a0_grid.min()), float(self.a0_grid.max())

    @property
    def tau_fit(self) -> FloatArray:
        """``omega0 t`` of the training span, shape (heldout_start,)."""
        return self.calibrated.tau[: self.heldout_start]

    @property
    def gap_fit(self) -> FloatArray | float:
        """Rest gap of the training span (/ L_ref): a number, or shape (heldout_start,)."""
        g = self.calibrated.gap
        return g if np.isscalar(g) else np.asarray(g)[: self.heldout_start]

    # ------------------------------------------------------------------ new problems
    def with_drive(self, rotation: float, rotated: bool) -> OrbitProblem:
        """The drive columns rotated to ``rotation``; boxed about ``F_c`` when ``rotated``."""
        return dataclasses.replace(self, rotation=float(rotation), drive_rotated=bool(rotated))

    def with_noise(self, noise_variance: float) -> OrbitProblem:
        """The calibration priors in units of this row noise variance."""
        return dataclasses.replace(self, noise_variance=float(noise_variance))

    # ------------------------------------------------------------------ rows
    def design(self, library: AFMLibrary, a0: float) -> JointDesign:
        """Rows, boxes and threshold pattern for ``library`` at ``a0`` (pure)."""
        b = self.bound
        lin = b.linear.copy()
        if self.rotation:
            c, s = lin[:, 2].copy(), lin[:, 3].copy()
            cr, sr = math.cos(self.rotation), math.sin(self.rotation)
            # cos(Ot - r) = cos cr + sin sr ; sin(Ot - r) = sin cr - cos sr
            lin[:, 2] = c * cr + s * sr
            lin[:, 3] = s * cr - c * sr
        fcol = b.force_columns(library, a0) if library.n_terms else np.empty((b.n_rows, 0))
        theta = np.concatenate([lin, -fcol], axis=1)
        p = theta.shape[1]
        cal, cons = self.calibrated, self.constraints
        fc = cal.drive_amplitude
        # unrotated (first pass): the drive is free, so the data set its phase
        rotated = fc is not None and self.drive_rotated
        lo, hi = cons.lever_boxes(p, quality_factor=cal.quality_factor,
                                  drive_amplitude=fc if rotated else None)
        if rotated:
            assert fc is not None
            tb = cons.box("drive")
            lo[3], hi[3] = -fc * tb, fc * tb
        if self.physical_signs:
            sg = np.array([t.sign for t in library.terms], int)
            lo[N_LIN:][sg > 0] = 0.0
            hi[N_LIN:][sg < 0] = 0.0
        # thresholds act on a term's RMS contribution: pattern_j = 1 / rms(theta_j) on the orbit
        pattern = np.zeros(p)
        if library.n_terms:
            d = self.denoised
            s = TermInput(z=self.gap_fit - d.x, zdot=-d.v, x=d.x, a0=a0)
            rms = np.sqrt(np.mean(library.evaluate(s) ** 2, axis=0))
            pattern[N_LIN:] = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 0.0)
        # columns that vanish (e.g. contact terms without contact) are pinned to zero
        dead = np.all(theta == 0, axis=0)
        lo[dead], hi[dead] = 0.0, 0.0
        return JointDesign(theta=theta, y=b.target, lower=lo, upper=hi, pattern=pattern,
                           library=library, a0=float(a0))

    def optimizer(self, des: JointDesign, threshold: float | None = None,
                  nu: float = 1.0) -> BoxSR3:
        """A BoxSR3 with the design's boxes; ``threshold`` defaults to the grid's smallest."""
        return des.optimizer(float(self.thresholds[0] if threshold is None else threshold), nu)

    def prior(self, p: int) -> tuple[FloatArray, FloatArray]:
        """Calibration priors as Gram additions ``(G0 (p, p), b0 (p,))``."""
        assert self.noise_variance is not None, "a noise stage sets noise_variance first"
        cal = self.calibrated
        return self.constraints.prior_gram(
            p, quality_factor=cal.quality_factor,
            drive_amplitude=cal.drive_amplitude if self.drive_rotated else None,
            drive_source=cal.drive_source, noise_variance=self.noise_variance)

    def gram(self, des: JointDesign) -> tuple[FloatArray, FloatArray]:
        """Normal equations with the priors: ``G (p, p)``, ``b (p,)``."""
        G0, b0 = self.prior(des.theta.shape[1])
        return des.theta.T @ des.theta + G0, des.theta.T @ des.y + b0

    def prior_rows(self, des: JointDesign) -> tuple[FloatArray, FloatArray]:
        """Rows with the prior as pseudo-rows, spread evenly over the CV blocks.

        Each of the ``nb`` blocks carries ``1/nb`` of the prior, so a rolling fold trained on
        ``f`` blocks sees ``f/nb`` of it (prior-to-data ratio fixed) and the fit on all rows sees
        exactly the prior of :meth:`prior`.
        """
        p = des.theta.shape[1]
        G0, b0 = self.prior(p)
        idx = np.flatnonzero(np.diag(G0) > 0)
        nb = len(self.blocks)
        pr = np.zeros((idx.size, p))
        w = np.sqrt(np.diag(G0)[idx] / nb)
        pr[np.arange(idx.size), idx] = w
        py = b0[idx] / np.diag(G0)[idx] * w
        th, yy = [], []
        for a, z in self.blocks:
            th += [des.theta[a:z], pr]
            yy += [des.y[a:z], py]
        return np.concatenate(th), np.concatenate(yy)

    def refit(self, des: JointDesign, support: NDArray[np.bool_]) -> FloatArray:
        """Constrained least squares (boxes and priors) on ``support``, shape (p,)."""
        G, b = self.gram(des)
        return self.optimizer(des).refit_gram(G, b, support)[0]

    def support_rss(self, library: AFMLibrary, a0: float) -> float:
        """Residual sum of squares of the full support of ``library`` at ``a0`` (inf:
        infeasible)."""
        des = self.design(library, a0)
        G, b = self.gram(des)
        try:
            c = self.optimizer(des).refit_gram(G, b, np.ones(G.shape[0], bool))[0]
        except (ValueError, np.linalg.LinAlgError):  # infeasible corner
            return np.inf
        r = des.y - des.theta @ c
        return float(r @ r)

    def cv(self, library: AFMLibrary, a0: float) -> FloatArray:
        """Rolling-CV errors (per fold) of the full support of ``library`` at ``a0``."""
        des = self.design(library, a0)
        supp = np.ones(des.theta.shape[1], bool)
        return cv_errors(self.optimizer(des), des.theta, des.y, self.blocks, supp,
                         prior=self.prior(des.theta.shape[1]))

    # ------------------------------------------------------------------ states
    def initial_state(self, i0: int) -> tuple[float, float]:
        """Denoised ``(x, x')`` at sample ``i0`` (start of a held-out simulation)."""
        hf = self.denoised.harmonic_fit
        cal = self.calibrated
        if hf is not None:
            t = cal.tau[i0]
            return float(hf.evaluate(np.array([t]))[0]), float(hf.evaluate(np.array([t]), 1)[0])
        w = default_window(cal.samples_per_period)
        a = max(i0 - 2 * w, 0)
        b = min(i0 + 2 * w, cal.n_samples)
        xs, xd, _ = savgol_derivatives(cal.x[a:b], float(cal.tau[1] - cal.tau[0]), window=w)
        return float(xs[i0 - a]), float(xd[i0 - a])

    def full_state(self) -> tuple[FloatArray, FloatArray]:
        """Denoised ``x``, ``x'`` on every sample of the record, each shape (n,)."""
        cal = self.calibrated
        if self.periodic:
            hf = self.denoised.harmonic_fit
            assert hf is not None
            return hf.evaluate(cal.tau), hf.evaluate(cal.tau, 1)
        w = default_window(cal.samples_per_period)
        xs, xd, _ = savgol_derivatives(cal.x, float(cal.tau[1] - cal.tau[0]), window=w)
        return xs, xd


def build_orbit_problem(cal: Calibrated, *, constraints: CalibrationConstraints,
                        projection: AbstractProjection | None, heldout_fraction: float,
                        n_folds: int, max_harmonics: int, min_harmonics: int,
                        thresholds: FloatArray | None, nus: FloatArray | None, n_a0: int,
                        a0_range_m: tuple[float, float] | None,
                        physical_signs: bool) -> OrbitProblem:
    """Split, denoise and project one record; the threshold and ``a0`` grids.

    Parameters
    ----------
    cal : Calibrated
        The record, dimensionless.
    projection : AbstractProjection or None
        None: :class:`HarmonicBalance` for periodic data, :class:`WeakForm` otherwise.
    heldout_fraction : float
        Share of the periods (at the end) kept out of every fit.
    n_folds : int
        Rolling cross-validation folds (``n_folds + 1`` row blocks).
    max_harmonics, min_harmonics : int
        Noise-floor search limit and smallest Fourier order of the periodic state.
    thresholds : ndarray, shape (n_t,), or None
        Threshold grid; None: ``geomspace(0.01, 10, 10) / Q`` times the orbit's RMS deflection.
    nus : ndarray, shape (n_nu,), or None
        Relaxation grid; None: ``geomspace(1, 1e4, 5)``.
    n_a0 : int
        Points of each geometric family of the ``a0`` grid.
    a0_range_m : (float, float) or None
        Physical ``a0`` range [m] (None: the orbit's own scale only).
    physical_signs : bool

    Raises
    ------
    ValueError
        When the record is too short for ``n_folds`` after the held-out split.
    """
    n = cal.n_samples
    spp = cal.samples_per_period
    # -- split
    n_periods = n / spp
    fit_periods = math.floor(n_periods * (1 - heldout_fraction))
    if fit_periods < n_folds + 1:
        raise ValueError(
            f"trace too short: {n_periods:.1f} periods leave {fit_periods} for fitting, "
            f"need >= n_folds + 1 = {n_folds + 1}")
    n_fit = int(round(fit_periods * spp))
    tau, x = cal.tau, cal.x
    gap = cal.gap
    gap_fit = gap if np.isscalar(gap) else np.asarray(gap)[:n_fit]
    # -- denoise
    periodic = False
    hf: HarmonicFit | None = None
    if np.isscalar(gap) and not isinstance(projection, WeakForm):
        hf = fit_harmonics(tau[:n_fit], x[:n_fit], cal.omega, max_harmonics=max_harmonics)
        # the noise-floor order keeps only harmonics above a 1 % family-wise false alarm;
        # the contact's shape lives in weaker ones, so the state keeps at least
        # `min_harmonics` (noise cost: sigma * sqrt((2 n_h + 1) / n_samples))
        nyq = max(int(spp / 2) - 1, 1)
        n_state = min(max(hf.n_harmonics, min_harmonics), nyq)
        if n_state != hf.n_harmonics:
            hf = fit_harmonics(tau[:n_fit], x[:n_fit], cal.omega, n_harmonics=n_state)
        periodic = bool(hf.is_periodic) or isinstance(projection, HarmonicBalance)
    if periodic:
        assert hf is not None
        den = Denoised(x=hf.evaluate(tau[:n_fit]), v=hf.evaluate(tau[:n_fit], 1),
                       harmonic_fit=hf)
        proj = projection or HarmonicBalance()
    else:
        win = default_window(spp)
        xs, xd, _ = savgol_derivatives(x[:n_fit], float(tau[1] - tau[0]), window=win)
        den = Denoised(x=xs, v=xd)
        proj = projection if isinstance(projection, WeakForm) else WeakForm()
    rdata = RegressionData(tau=tau[:n_fit], x=x[:n_fit], omega=cal.omega,
                           quality_factor=cal.quality_factor,
                           gap=gap_fit if np.isscalar(gap_fit) else np.asarray(gap_fit),
                           samples_per_period=spp, denoised=den)
    bound = proj.bind(rdata, n_blocks=n_folds + 1)
    # -- threshold grid
    z_orbit = np.asarray(gap_fit) - den.x
    rms_x = float(np.sqrt(np.mean((den.x - den.x.mean()) ** 2))) or 1.0
    q = cal.quality_factor
    ts = (np.geomspace(0.01, 10.0, 10) / q * rms_x if thresholds is None
          else np.atleast_1d(np.asarray(thresholds, float)))
    nu_grid = (np.geomspace(1.0, 1e4, 5) if nus is None
               else np.atleast_1d(np.asarray(nus, float)))
    # -- a0 grid: contact depths a0 - zmin and absolute a0 (both geometric, 0.1 % to 30 % of
    # the orbit's gap span; a0 > 0 since long-range terms are held at a0 in contact), plus
    # "no contact" (a0 below the orbit) when the orbit stays at positive gaps
    zmin, zmax = float(np.min(z_orbit)), float(np.max(z_orbit))
    span = max(zmax - zmin, 1e-9)
    g = np.geomspace(1e-3 * span, 0.3 * span, n_a0)
    a0_grid = np.unique(np.concatenate([zmin + g, g]))
    a0_grid = a0_grid[(a0_grid > max(zmin, 0.0)) & (a0_grid <= zmin + 0.3 * span)]
    if a0_range_m is not None:
        # a0 is an intermolecular distance: keep the physical range (SI / L_ref), where
        # the profile is nearly flat along (a0, exponent, stiffness) and would otherwise
        # drift to sub-atomic onsets with steep exponents
        lo_a, hi_a = (v / cal.scales.length for v in a0_range_m)
        phys = np.geomspace(max(lo_a, zmin + 1e-3 * span), hi_a, n_a0) if (
            hi_a > max(lo_a, zmin + 1e-3 * span)) else np.empty(0)
        a0_grid = np.unique(np.concatenate([a0_grid, phys]))
        a0_grid = a0_grid[(a0_grid >= lo_a) & (a0_grid <= hi_a) & (a0_grid > zmin)]
    if zmin - 0.01 * span > 0:
        a0_grid = np.concatenate([[zmin - 0.01 * span], a0_grid])
    if a0_grid.size == 0:  # the orbit never reaches the physical contact range
        a0_grid = np.array([zmin - 0.01 * span])
    return OrbitProblem(calibrated=cal, constraints=constraints, bound=bound, denoised=den,
                        periodic=periodic, projection=proj, heldout_start=n_fit,
                        heldout_reference=_heldout_reference(cal, n_fit, den, periodic),
                        thresholds=ts, nus=nu_grid, a0_grid=a0_grid, orbit_span=span,
                        physical_signs=physical_signs)


def _heldout_reference(cal: Calibrated, i0: int, den: Denoised, periodic: bool
                       ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Held-out ``x``, ``x'``, ``x''`` denoised on their own (never used in fitting)."""
    tau, x = cal.tau[i0:], cal.x[i0:]
    hf = den.harmonic_fit
    if hf is not None and periodic:
        h = fit_harmonics(tau, x, cal.omega, n_harmonics=min(hf.n_harmonics,
                                                             max(x.size // 4 - 1, 1)))
        return h.evaluate(tau), h.evaluate(tau, 1), h.evaluate(tau, 2)
    w = default_window(cal.samples_per_period)
    xs, xd, xdd = savgol_derivatives(x, float(tau[1] - tau[0]), window=w)
    return xs, xd, xdd
