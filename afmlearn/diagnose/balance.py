"""Harmonic balance on the measured periodic orbit, whitened by the linearised dynamics.

For a steady orbit ``x(tau)`` with harmonics ``X_n`` (``x = Re sum_n X_n e^{i n theta}``,
``theta = Omega tau``) the equation of motion of a :class:`ModelSpec` becomes one complex row
per harmonic ``n = 0 .. n_h``::

    e_n = (K - n^2 Omega^2 + i n Omega D) X_n / G_n + F_n - B e^{-i phi} [n = 1]

with ``F_n`` the harmonics of the force columns evaluated on the measured (denoised) orbit and
``G_n = 1 + g2 L1_n H2_n`` the second mode's share of the lever's response (``G = 1`` for one
mode). The rows are linear in ``(K, D, B, c_j)``; the other parameters (``a0``, ``phi``,
exponents, decay lengths, mode 2, detector) are nonlinear and searched outside.

Noise model (what makes the residual a chi-square). The measured orbit's harmonics carry white
noise of standard deviation ``sigma sqrt(2 / N)`` (``sigma`` the sample noise, ``N`` the fitted
samples). A perturbation ``dX`` of the orbit changes the rows by ``J dX``, where ``J`` is the
Hill operator of the equation linearised about the orbit (lever plus ``dF/dx`` and
``dF/dx'`` of a reference fit). The whitened residual ``w = diag(1/sigma_X) J^-1 e`` is
therefore the orbit correction the model needs, in units of the orbit's own noise: for the
true model ``||w||^2`` is chi-square with (rows - parameters) degrees of freedom, and the
difference between two nested models is a likelihood-ratio statistic. Calibration priors
(``K = 1``, ``D = 1/Q``, ``B = F_c``; physics.md section 5) enter as extra rows in the same
units, with boxes of +-15 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import lsq_linear

from afmlearn.preprocess import HarmonicFit

from ._kernel import bvls
from .spec import ModelSpec

__all__ = ["PeriodicOrbit", "HarmonicBalance", "Solution", "bounded_lstsq", "N_LEVER",
           "harmonics", "to_real", "from_real", "synthesize"]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: linear lever/drive unknowns that precede the force coefficients: K, D, B
N_LEVER = 3


def harmonics(u: FloatArray, n_h: int) -> ComplexArray:
    """``U_n`` (n = 0..n_h) of a grid function over one period: ``u = Re sum U_n e^{i n theta}``.

    ``u`` shape (..., M) on ``theta_k = 2 pi k / M``; returns shape (..., n_h + 1).
    """
    m = u.shape[-1]
    f = np.fft.rfft(u, axis=-1)[..., : n_h + 1] / m
    f[..., 1:] *= 2.0
    return f


def synthesize(U: ComplexArray, m: int, derivative: int = 0, omega: float = 1.0) -> FloatArray:
    """Grid values (M points) of ``Re sum U_n (i n Omega)^d e^{i n theta}``."""
    n = np.arange(U.shape[-1])
    spec = U * (1j * n * omega) ** derivative
    full = np.zeros(m // 2 + 1, complex)
    full[: spec.size] = spec
    full[1:] /= 2.0
    return np.fft.irfft(full * m, n=m)


def to_real(E: ComplexArray) -> FloatArray:
    """Real rows ``[Re E_0, Re E_1..n, -Im E_1..n]`` (the HarmonicFit coefficient layout)."""
    return np.concatenate([E[..., :1].real, E[..., 1:].real, -E[..., 1:].imag], axis=-1)


def from_real(r: FloatArray) -> ComplexArray:
    """Inverse of :func:`to_real`."""
    n = (r.shape[-1] - 1) // 2
    out = np.empty(r.shape[:-1] + (n + 1,), complex)
    out[..., 0] = r[..., 0]
    out[..., 1:] = r[..., 1 : n + 1] - 1j * r[..., n + 1 :]
    return out


@final
class PeriodicOrbit:
    """The denoised measured orbit of the fit span on a phase grid of one drive period.

    Parameters
    ----------
    fit : HarmonicFit
        Fourier series of the measured deflection (``period_multiple`` 1) over the fit span.
    gap : float
        Rest gap / ``L_ref``.
    quality_factor : float
        Calibrated Q of the free fundamental.
    drive_amplitude : float or None
        ``F_c`` [k L_ref] from the free data (None: the drive amplitude is not constrained).
    grid : int
        Phase-grid points per period (power of two; resolves the contact).

    Attributes
    ----------
    y, ydot : ndarray, shape (grid,)
        Measured orbit and rate on ``theta_k = 2 pi k / grid`` (``tau = theta / Omega``).
    Y : ndarray, shape (n_h + 1,), complex
        Its harmonics.
    sigma_rows : ndarray, shape (2 n_h + 1,)
        Noise standard deviation of each real harmonic coefficient.
    """

    def __init__(self, fit: HarmonicFit, *, gap: float, quality_factor: float,
                 drive_amplitude: float | None, grid: int = 4096) -> None:
        self.omega = float(fit.omega)
        self.n_h = int(fit.n_harmonics)
        self.gap = float(gap)
        self.quality_factor = float(quality_factor)
        self.drive_amplitude = drive_amplitude
        self.grid = int(grid)
        self.Y = fit.complex_amplitudes.copy()
        self.y = synthesize(self.Y, self.grid)
        self.ydot = synthesize(self.Y, self.grid, 1, self.omega)
        sig = float(fit.noise_rms)
        n = max(int(fit.n_samples), 1)
        self.noise_rms = sig
        self.sigma_rows = np.full(2 * self.n_h + 1, sig * math.sqrt(2.0 / n))
        self.sigma_rows[0] = sig / math.sqrt(n)
        self.theta = 2.0 * np.pi * np.arange(self.grid) / self.grid

    def true_orbit(self, spec: ModelSpec) -> tuple[FloatArray, FloatArray, ComplexArray]:
        """Deflection, rate on the grid and harmonics of the true tip motion under ``spec``."""
        if spec.output_map is None:
            return self.y, self.ydot, self.Y
        x = spec.output_map.invert(self.y)
        X = harmonics(x, self.n_h)
        return synthesize(X, self.grid), synthesize(X, self.grid, 1, self.omega), X


def bounded_lstsq(A: FloatArray, b: FloatArray, P: FloatArray, t: FloatArray, lo: FloatArray,
                  hi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Bounded linear least squares of the whitened rows ``A c = b`` and the prior rows
    ``P c = t`` (BVLS on unit-norm columns, for conditioning).

    Parameters
    ----------
    A : ndarray, shape (m, p)
        Whitened data rows; ``b`` shape (m,).
    P : ndarray, shape (k, p)
        Calibration-prior rows (sigma units); ``t`` shape (k,).
    lo, hi : ndarray, shape (p,)
        Bounds of the coefficients.

    Returns
    -------
    coef : ndarray, shape (p,)
    residual : ndarray, shape (m + k,)
        ``[A; P] coef - [b; t]``; all ``inf`` (coef NaN) when the rows are not finite (a
        structure with no finite columns on this orbit: the caller rejects it).
    """
    Af = np.vstack([A, P])
    bf = np.concatenate([b, t])
    if not (np.all(np.isfinite(Af)) and np.all(np.isfinite(bf))):
        # measured: a non-finite column made LAPACK raise "SVD did not converge" from inside
        # a one-orbit diagnosis (step 2 after a detector map)
        return np.full(Af.shape[1], np.nan), np.full(bf.size, np.inf)
    scale = np.linalg.norm(Af, axis=0)
    scale[scale == 0] = 1.0
    As, lo_s, hi_s = Af / scale, lo * scale, hi * scale
    p = As.shape[1]
    if As.shape[0] > p and np.all(lo_s < hi_s):
        # the problem reduced by one QR of [A b] (R, Q^T b and the part of |b|^2 no
        # coefficient reaches), then SciPy's BVLS algorithm compiled: equal to
        # ``lsq_linear(method="bvls")`` to 1e-14 (tests), without its per-call Python work
        # (measured: 52 % of a diagnosis without recorded phases was spent in lsq_linear)
        Rb = np.linalg.qr(np.column_stack([As, bf]), mode="r")
        y = bvls(np.ascontiguousarray(Rb[:p, :p]), Rb[:p, p].copy(), float(Rb[p, p] ** 2),
                 lo_s, hi_s)
    else:
        y = lsq_linear(As, bf, bounds=(lo_s, hi_s), method="bvls", lsmr_tol="auto").x
    coef = y / scale
    return coef, Af @ coef - bf


@final
@dataclass
class Solution:
    """A fitted candidate: ``coef = [K, D, B, c_1..c_m]``, whitened residual, chi2.

    ``values`` are the nonlinear parameters that built ``spec`` (``a0`` and the extension's,
    in the order of its parameters), when known. ``phases`` are the drive phases of the
    observations of a joint fit (``spec.drive_phase`` is then a placeholder; the model at
    observation ``i`` has drive phase ``phases[i]``).
    """

    spec: ModelSpec
    coef: FloatArray
    residual: FloatArray
    chi2: float
    values: tuple[float, ...] = ()
    phases: tuple[float, ...] = ()


@final
class HarmonicBalance:
    """Whitened harmonic-balance least squares for :class:`ModelSpec` candidates.

    Parameters
    ----------
    orbit : PeriodicOrbit
    stiffness_prior : float
        Relative standard deviation of the prior ``K = 1``. ``K = (f_free / f0)^2`` is fixed
        by the resonance frequency of the thermal tune (known to ~1e-4); a wrong spring
        constant only rescales the force unit. A loose prior would let ``K`` absorb the
        softening of any long-range force (the electrostatic signature).
    prior_rel : float
        Relative standard deviation of the priors ``D = 1/Q`` and ``B = F_c`` (Q and the free
        amplitude are known to a few per cent).
    box_rel : float
        Half width of the boxes on ``D`` and ``B`` (relative); ``K``'s box is 10 prior widths.
    """

    def __init__(self, orbit: PeriodicOrbit, *, stiffness_prior: float = 1e-3,
                 prior_rel: float = 0.05, box_rel: float = 0.15) -> None:
        self.orbit = orbit
        self.stiffness_prior = float(stiffness_prior)
        self.prior_rel = float(prior_rel)
        self.box_rel = float(box_rel)
        o = orbit
        n = np.arange(o.n_h + 1)
        self._n = n
        self._d0 = 1.0 / o.quality_factor
        self._lever0 = 1.0 - (n * o.omega) ** 2 + 1j * n * o.omega * self._d0
        # lever-only whitening until a reference model sets the full Hill operator
        self.set_whitening(None)

    # ------------------------------------------------------------------ whitening
    def set_whitening(self, reference: Solution | None) -> None:
        """Whitening ``diag(1/sigma) J^-1`` from the Hill operator of ``reference``.

        None: the lever alone with the calibrated ``K = 1``, ``D = 1/Q``.
        """
        o = self.orbit
        nh = o.n_h
        nb = 2 * nh + 1
        m = o.grid
        th = o.theta
        k = np.arange(1, nh + 1)
        basis = np.empty((m, nb))
        basis[:, 0] = 1.0
        basis[:, 1 : nh + 1] = np.cos(np.outer(th, k))
        basis[:, nh + 1 :] = np.sin(np.outer(th, k))
        dbasis = np.zeros_like(basis)
        dbasis[:, 1 : nh + 1] = -o.omega * k * basis[:, nh + 1 :]
        dbasis[:, nh + 1 :] = o.omega * k * basis[:, 1 : nh + 1]
        K, D = 1.0, self._d0
        fx = fv = np.zeros(m)
        if reference is not None:
            K, D = float(reference.coef[0]), float(reference.coef[1])
            fx, fv = self._force_gradients(reference)
        # lever part: diagonal in (cos, sin) pairs
        J = np.zeros((nb, nb))
        J[0, 0] = K
        w = o.omega * k
        J[k, k] = K - w**2
        J[k + nh, k + nh] = K - w**2
        J[k + nh, k] = -D * w      # cos -> -D w sin : coefficient of sin
        J[k, k + nh] = D * w       # sin -> +D w cos
        proj = basis.T * (2.0 / m)
        proj[0] *= 0.5
        J += proj @ (fx[:, None] * basis + fv[:, None] * dbasis)
        inv = np.linalg.pinv(J, rcond=1e-10)
        self._W = inv / o.sigma_rows[:, None]
        self._cache: dict[ModelSpec, tuple[FloatArray, ...]] = {}

    def _force_gradients(self, sol: Solution) -> tuple[FloatArray, FloatArray]:
        """``dF/dx`` and ``dF/dx'`` along the orbit for the reference solution's force."""
        o = self.orbit
        spec = sol.spec
        x, v, _ = o.true_orbit(spec)
        z, zd = o.gap - x, -v
        c = sol.coef[N_LEVER:N_LEVER + spec.n_force]     # (a joint fit's other drives follow)
        att = spec.state(z)
        h = 1e-6 * max(float(np.ptp(z)), 1e-9)
        fz = (spec.columns(z + h, zd, att) - spec.columns(z - h, zd, att)) @ c / (2 * h)
        hv = 1e-6 * max(float(np.ptp(zd)), 1e-9)
        fzd = (spec.columns(z, zd + hv, att) - spec.columns(z, zd - hv, att)) @ c / (2 * hv)
        return -fz, -fzd

    # ------------------------------------------------------------------ rows
    def design(self, spec: ModelSpec, phase: float | None = None
               ) -> tuple[FloatArray, FloatArray]:
        """Whitened design ``A`` (rows, N_LEVER + n_force) and target ``b`` for ``spec``
        (drive phase ``phase``, default ``spec.drive_phase``).

        The force and lever columns do not depend on the drive phase; they are cached per
        structure (cleared when the whitening changes), so a change of the phase alone costs
        two columns.
        """
        A0, b, w_cos, w_sin = self.parts(spec)
        A = A0.copy()
        ph = spec.drive_phase if phase is None else phase
        A[:, 2] = -(math.cos(ph) * w_cos + math.sin(ph) * w_sin)
        return A, b

    def parts(self, spec: ModelSpec) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """:meth:`design_parts`, cached per structure (the drive phase does not enter)."""
        key = spec if spec.drive_phase == 0.0 else spec.replace(drive_phase=0.0)
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) > 512:
                self._cache.clear()
            hit = self.design_parts(spec)
            self._cache[key] = hit
        return hit

    def design_parts(self, spec: ModelSpec
                     ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Whitened lever and force columns (drive column zero), target, and the whitened
        drive basis ``W[:, 1]``, ``W[:, n_h + 1]`` (cos and sin of the phase)."""
        o = self.orbit
        n = self._n
        x, v, X = o.true_orbit(spec)
        z, zd = o.gap - x, -v
        cols = spec.columns(z, zd, spec.state(z))             # (M, m)
        F = harmonics(cols.T, o.n_h)                          # (m, n_h + 1)
        G = np.ones(n.size, complex)
        mode = spec.extra_mode
        if mode is not None:
            G = 1.0 + mode.mode_parameters()[2] * self._lever0 * mode.response(n, o.omega)
        XG = X / G
        drive = np.zeros(n.size, complex)                     # the phase goes in by design()
        A = np.vstack([XG, 1j * n * o.omega * XG, drive, F])  # (N_LEVER + m, n_h + 1)
        b = (n * o.omega) ** 2 * XG
        Ar = to_real(A).T
        br = to_real(b)
        # drive column -e^{-i phi} at n = 1: real rows 1 (-cos phi) and n_h + 1 (-sin phi)
        return (self._W @ Ar, self._W @ br, self._W[:, 1].copy(),
                self._W[:, 1 + o.n_h].copy())

    def bounds(self, spec: ModelSpec) -> tuple[FloatArray, FloatArray]:
        """Boxes of ``[K, D, B, c_1..c_m]``: calibration boxes and physical signs."""
        p = N_LEVER + spec.n_force
        fc = self.orbit.drive_amplitude
        box, sk = self.box_rel, self.stiffness_prior
        lo = np.full(p, -np.inf)
        hi = np.full(p, np.inf)
        lo[0], hi[0] = 1 - 10 * sk, 1 + 10 * sk
        lo[1], hi[1] = self._d0 * (1 - box), self._d0 * (1 + box)
        if fc is not None and fc > 0:
            lo[2], hi[2] = fc * (1 - box), fc * (1 + box)
        else:
            lo[2] = 0.0
        for j, s in enumerate(spec.signs()):
            if s > 0:
                lo[N_LEVER + j] = 0.0
            elif s < 0:
                hi[N_LEVER + j] = 0.0
        return lo, hi

    def prior_rows(self, p: int) -> tuple[FloatArray, FloatArray]:
        """Prior rows ``P`` and targets ``t`` (residual ``P coef - t``, in sigma units)."""
        fc = self.orbit.drive_amplitude
        rel, sk = self.prior_rel, self.stiffness_prior
        rows = [np.eye(p)[0] / sk, np.eye(p)[1] / (rel * self._d0)]
        t = [1.0 / sk, 1.0 / rel]
        if fc is not None and fc > 0:
            rows.append(np.eye(p)[2] / (rel * fc))
            t.append(1.0 / rel)
        return np.array(rows), np.array(t)

    def prior_residual(self, coef: FloatArray) -> FloatArray:
        """The calibration-prior rows of the residual for ``coef`` (sigma units)."""
        P, t = self.prior_rows(coef.size)
        return P @ coef - t

    def solve(self, spec: ModelSpec, values: tuple[float, ...] = ()) -> Solution:
        """Bounded linear least squares of the whitened rows plus calibration priors."""
        A, b = self.design(spec)
        lo, hi = self.bounds(spec)
        coef, r = bounded_lstsq(A, b, *self.prior_rows(A.shape[1]), lo, hi)
        return Solution(spec=spec, coef=coef, residual=r, chi2=float(r @ r),
                        values=tuple(values))
