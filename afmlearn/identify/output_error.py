"""Output-error stage of the joint fit: the law's own orbits against the measured deflection.

The harmonic-balance rows (:mod:`afmlearn.identify.problem`) evaluate the force terms on each
observation's *denoised* orbit. Near the turning point that orbit is known only to the noise
and truncation of its Fourier series, differently in every set-point, and a contact force is
so steep there that the rows of different set-points disagree about one law: the joint
equation-error fit then trades damping, drive and an ``x^3`` term against the contact law
(measured: ``p`` 2.25 for true 1.5, 2.0 and 2.27 alike). This stage removes the approximation.
For a parameter vector (``K``, ``D``, ``B``, ``a0``, the dominant contact exponent, the force
coefficients of the chosen support) every observation's periodic orbit is found by Newton
shooting on the one-period map of the ONE compiled kernel
(:func:`afmlearn.identify._simulate.simulate_period`, switches at ``a0`` located), and its
harmonics are compared with the measured ones in units of their noise:

    chi2 = sum_i sum_k |X_ik(theta) e^{-i k phi_i} - Y_ik|^2 / s_ik^2 + calibration priors

``Y_ik`` are the measured harmonics of observation ``i`` (least squares over all its periods;
``s_ik`` the noise of one real coefficient, ``sigma_i sqrt(2 / n_i)``, ``sigma_i sqrt(1 /
n_i)`` for the mean), ``X_ik`` those of the model's phase-0 orbit at the observation's rest
gap. The drive phase ``phi_i`` is projected out in closed form (:func:`align_phase`: the steady
orbit of ``B cos(Omega tau - phi)`` is the phase-0 orbit delayed by ``phi / Omega``), under
the recorded phase's prior where there is one. ``chi2`` is ``-2 log`` likelihood of "measured
= model orbit + white noise", so the exponent's profile over it (:class:`OutputErrorProfile`,
everything else re-optimised at each exponent) is the profile likelihood the interval and the
``bounded`` flag come from. When the law cannot fit every orbit to the noise, ``chi2 / dof``
exceeds 1 and the profile's threshold is scaled by it (quasi-likelihood), so a misfit widens
the interval instead of making a wrong law look certain.

The rest gaps are taken as recorded (the simulated orbit needs no gap offset: the offsets of
the equation-error stage corrected the denoised orbit's error, which does not arise here).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from afmlearn.preprocess import fit_harmonics
from afmlearn.preprocess.phase import align_phase, wrap_angle

from ._simulate import simulate_period
from .library import AFMLibrary, Indentation
from .problem import N_LEVER, JointProblem

__all__ = ["MeasuredHarmonics", "OutputErrorFit", "OutputErrorLaw", "OutputErrorProfile",
           "OutputErrorResult", "OutputErrorStage", "OutputErrorSupport", "align_phase",
           "covariance_samples", "measured_harmonics", "periodic_orbit"]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: starts of a fixed-exponent fit: ``(law, u, p) -> [u0, ...]``
Restarts = Callable[["OutputErrorLaw", NDArray[np.float64], float], list[NDArray[np.float64]]]

#: a residual returned for a parameter vector whose orbit cannot be found (a barrier)
_FAIL = 1e4


# ---------------------------------------------------------------------------- data
@final
@dataclass(frozen=True, eq=False)
class MeasuredHarmonics:
    """Measured harmonics of every observation (common units, lengths / ``L_ref``).

    Attributes
    ----------
    Y : ndarray, shape (n_obs, n_h + 1), complex
        ``Y_ik``: ``x_i(tau) = Re sum_k Y_ik e^{i k Omega tau}`` (tau from the record's first
        sample).
    sigma : ndarray, shape (n_obs, n_h + 1)
        Noise standard deviation of the real and of the imaginary part of ``Y_ik`` (the mean,
        ``k = 0``, has no imaginary part).
    start : ndarray, shape (n_obs, 2)
        ``(x, x')`` of the phase-0 orbit at ``tau = 0`` read from the measured orbit
        (a shooting start; refined per observation as the fit proceeds).
    """

    Y: ComplexArray
    sigma: FloatArray
    start: FloatArray

    @property
    def n_harmonics(self) -> int:
        return int(self.Y.shape[1] - 1)


def measured_harmonics(problem: JointProblem, n_harmonics: int) -> MeasuredHarmonics:
    """Harmonics 0..``n_harmonics`` of every observation and their noise (one pass each).

    The start state of observation ``i`` is its measured orbit at ``tau = phi_i / Omega``
    with ``phi_i`` its recorded (or, for a free drive, its fundamental's) phase.
    """
    Y, S, st = [], [], []
    for i, o in enumerate(problem.observations):
        spp = o.calibrated.samples_per_period
        h = max(min(int(n_harmonics), int(spp / 2) - 1), 1)
        hf = fit_harmonics(o.tau, o.x, o.omega, n_harmonics=h)
        y = np.zeros(n_harmonics + 1, complex)
        y[:h + 1] = hf.complex_amplitudes
        n = o.x.size
        s = np.full(n_harmonics + 1, hf.noise_rms * math.sqrt(2.0 / n))
        s[0] = hf.noise_rms * math.sqrt(1.0 / n)
        s[h + 1:] = np.inf  # not measured: no weight
        Y.append(y)
        S.append(np.maximum(s, 1e-300))
        rot = problem.rotations[i]
        phi = float(rot) if math.isfinite(rot) else -float(np.angle(y[1]))
        t0 = np.array([phi / o.omega])
        hs = o.harmonic_fit  # the noise-floor order: a smoother velocity than all harmonics
        st.append((float(hs.evaluate(t0)[0]), float(hs.evaluate(t0, 1)[0])))
    return MeasuredHarmonics(Y=np.array(Y), sigma=np.array(S), start=np.array(st))


# ---------------------------------------------------------------------------- orbit
def periodic_orbit(state: FloatArray, *, n_out: int, substeps: int, gap: float, K: float,
                   D: float, B: float, omega: float, law: tuple[FloatArray, ...], a0: float,
                   jac: FloatArray | None = None, max_iter: int = 30, tol: float = 1e-9,
                   settle_periods: int = 0
                   ) -> tuple[FloatArray, FloatArray, FloatArray | None, bool]:
    """The model's periodic orbit through (near) ``state`` at ``tau = 0`` (drive phase 0).

    Newton shooting on ``P(s) = s`` (``P``: one period of the compiled kernel), with the
    finite-difference monodromy ``jac`` reused while the residual falls tenfold per step
    (chord) and recomputed otherwise; steps are limited to 20 % of the state's scale. If
    that fails and ``settle_periods > 0``, the model is integrated that many periods from
    ``state`` (onto its attractor) and shooting starts again from there.

    Returns the deflection at ``n_out`` equally spaced phases (shape (n_out,)), the orbit's
    state at ``tau = 0`` (2,), the last monodromy (2, 2) and whether shooting converged.
    """
    kinds, p1, p2, cf = law

    def pmap(s: FloatArray) -> tuple[FloatArray, FloatArray]:
        xs, xe, ve = simulate_period(float(s[0]), float(s[1]), n_out, substeps, gap, K, D, B,
                                     omega, kinds, p1, p2, cf, a0)
        return xs, np.array([xe, ve])

    s = np.array(state, float)
    J = None if jac is None else jac.copy()
    xs, s1, J1, ok = _shoot(pmap, s, J, max_iter, tol)
    if ok or settle_periods <= 0:
        return xs, s1, J1, ok
    for _ in range(int(settle_periods)):
        s = pmap(s)[1]
        if not np.all(np.isfinite(s)):
            return xs, s1, J1, False
    return _shoot(pmap, s, None, max_iter, tol)


def _shoot(pmap: Any, s: FloatArray, J: FloatArray | None, max_iter: int, tol: float
           ) -> tuple[FloatArray, FloatArray, FloatArray | None, bool]:
    # the state is two numbers: plain float arithmetic (numpy's per-call overhead on 2-vectors
    # was most of the shooting's Python time); the 2 x 2 Newton step by Cramer's rule
    last = math.inf
    for _ in range(max_iter):
        xs, ps = pmap(s)
        r0, r1 = float(ps[0] - s[0]), float(ps[1] - s[1])
        if not (math.isfinite(r0) and math.isfinite(r1)):
            return xs, s, None, False
        scale = max(abs(float(s[0])), abs(float(s[1])), 1e-3)
        err = max(abs(r0), abs(r1))
        if err < tol * scale:
            return xs, s, J, True
        if J is None or err > 0.1 * last:
            J = np.empty((2, 2))
            h = 1e-7 * scale
            for j in range(2):
                sp = s.copy()
                sp[j] += h
                J[:, j] = (pmap(sp)[1] - ps) / h
        last = err
        a, b, c, d = J[0, 0] - 1.0, J[0, 1], J[1, 0], J[1, 1] - 1.0
        det = a * d - b * c
        if not math.isfinite(det) or abs(det) <= 1e-14 * max(abs(a * d), abs(b * c), 1e-300):
            return xs, s, None, False
        st0, st1 = (-r0 * d + b * r1) / det, (-a * r1 + c * r0) / det
        m = max(abs(st0), abs(st1))
        if m > 0.2 * scale:
            st0, st1 = st0 * 0.2 * scale / m, st1 * 0.2 * scale / m
        s = np.array([s[0] + st0, s[1] + st1])
    xs, ps = pmap(s)
    e0, e1 = float(ps[0] - s[0]), float(ps[1] - s[1])
    ok = math.isfinite(e0) and math.isfinite(e1) and max(abs(e0), abs(e1)) < 1e-6 * max(
        abs(float(s[0])), abs(float(s[1])), 1e-3)
    return xs, s, J, ok


# ---------------------------------------------------------------------------- the law
@final
@dataclass(frozen=True, eq=False)
class OutputErrorLaw:
    """Parameter layout of the output-error fit for one support.

    ``u = [K, D, B, a0, (p), c_1 .. c_m]``: lever stiffness, damping and drive amplitude,
    contact onset, the exponent of ``library.terms[exponent_index]`` (absent when
    ``exponent_index`` is None) and the force coefficients (``F_ts = sum_j c_j theta_j``).
    """

    library: AFMLibrary
    exponent_index: int | None

    @property
    def n_head(self) -> int:
        return 4 + (self.exponent_index is not None)

    def library_at(self, u: FloatArray) -> AFMLibrary:
        if self.exponent_index is None:
            return self.library
        return self.library.replace(self.exponent_index, Indentation(float(u[4])))

    def encoded(self, u: FloatArray) -> tuple[FloatArray, ...]:
        kinds, p1, p2 = self.library_at(u).encode()
        return kinds, p1, p2, np.ascontiguousarray(u[self.n_head:], float)


@final
@dataclass(frozen=True, eq=False)
class OutputErrorResult:
    """What :class:`OutputErrorFit` found (immutable).

    Attributes
    ----------
    law : OutputErrorLaw
    u : ndarray, shape (n_head + n_terms,)
        ``[K, D, B, a0, (p), c...]`` (lengths / ``L_ref``, forces / ``k L_ref``).
    phases : ndarray, shape (n_obs,)
        Drive phase ``phi_i`` of ``B cos(Omega tau - phi_i)`` [rad].
    chi2 : float
        Noise-weighted misfit plus priors at ``u``.
    dof : int
        Residuals minus fitted parameters (phases included).
    converged : bool
        Every observation's orbit was found by shooting.
    covariance : ndarray, shape (n_u, n_u)
        Gauss--Newton covariance of ``u`` (scaled by ``max(1, chi2 / dof)``; NaN if singular).
    nfev : int
    """

    law: OutputErrorLaw
    u: FloatArray
    phases: FloatArray
    chi2: float
    dof: int
    converged: bool
    covariance: FloatArray
    nfev: int = 0

    @property
    def library(self) -> AFMLibrary:
        return self.law.library_at(self.u)

    @property
    def a0(self) -> float:
        return float(self.u[3])

    @property
    def exponent(self) -> float | None:
        return None if self.law.exponent_index is None else float(self.u[4])

    @property
    def dispersion(self) -> float:
        return max(1.0, self.chi2 / max(self.dof, 1))

    def coef(self, problem: JointProblem) -> FloatArray:
        """Coefficients in the joint layout ``[-D, -K, drive..., c...]`` of ``problem``."""
        K, D, B = (float(v) for v in self.u[:3])
        out = np.zeros(problem.n_lin + self.law.library.n_terms)
        out[0], out[1] = -D, -K
        rot = problem.rotated
        if rot.any():
            out[N_LEVER] = B
            for k, i in enumerate(np.flatnonzero(rot)):
                out[N_LEVER + 1 + k] = B * math.sin(float(self.phases[i] - problem.rotations[i]))
        j = problem.n_lin - 2 * int((~rot).sum())
        ratios = problem.drive_ratios
        for i in np.flatnonzero(~rot):
            b_i = B * float(ratios[i])
            out[j], out[j + 1] = b_i * math.cos(self.phases[i]), b_i * math.sin(self.phases[i])
            j += 2
        out[problem.n_lin:] = self.u[self.law.n_head:]
        return out


# ---------------------------------------------------------------------------- objective
@dataclass(eq=False)
class _Objective:
    """Residual vector of one fit (holds the shooting warm starts of ONE run; not shared)."""

    problem: JointProblem
    meas: MeasuredHarmonics
    law: OutputErrorLaw
    n_out: int
    substeps: int
    fixed: dict[int, float] = field(default_factory=dict)
    #: ``(p_low, n)``: ``max(substeps, n)`` RK4 steps per sample while a ``delta^p`` of the
    #: law has ``p < p_low`` (:class:`OutputErrorFit`)
    low_exponent: tuple[float, int] = (0.0, 1)
    states: FloatArray = field(init=False)
    jacs: list[FloatArray | None] = field(init=False)
    ok: bool = field(init=False, default=True)
    phases: FloatArray = field(init=False)
    found: NDArray[np.bool_] = field(init=False)

    def __post_init__(self) -> None:
        self.states = self.meas.start.copy()
        self.jacs = [None] * self.problem.n_obs
        self.phases = np.zeros(self.problem.n_obs)
        self.found = np.zeros(self.problem.n_obs, bool)

    def full(self, free: FloatArray) -> FloatArray:
        if not self.fixed:
            return np.asarray(free, float)
        n = free.size + len(self.fixed)
        u = np.empty(n)
        mask = np.ones(n, bool)
        for j, v in self.fixed.items():
            u[j] = v
            mask[j] = False
        u[mask] = free
        return u

    def priors(self, u: FloatArray) -> list[float]:
        pb = self.problem
        cons = pb.constraints
        out = []
        for idx, mean, name in ((0, 1.0, "stiffness"), (1, 1.0 / pb.quality_factor, "damping")):
            w = cons.prior(name)
            if w is not None:
                out.append((u[idx] - mean) / (w * mean))
        fc = pb.drive_amplitude
        if fc is not None:
            w = cons.prior("drive", pb.drive_source)
            if w is not None:
                out.append((u[2] - fc) / (w * fc))
        return out

    def __call__(self, free: FloatArray) -> FloatArray:
        u = self.full(free)
        pb, meas = self.problem, self.meas
        K, D, B, a0 = (float(v) for v in u[:4])
        law = self.law.encoded(u)
        sub = self.substeps
        if self.low_exponent[1] > sub and _min_exponent(self.law, u) < self.low_exponent[0]:
            sub = self.low_exponent[1]
        nh = meas.n_harmonics
        ratios = pb.drive_ratios
        res = []
        ok = True
        for i, o in enumerate(pb.observations):
            # an observation whose orbit was never found yet may settle onto it first
            settle = 0 if self.found[i] else min(int(9.0 / (math.pi * max(D, 1e-6))), 3000)
            xs, s, J, conv = periodic_orbit(self.states[i], n_out=self.n_out,
                                            substeps=sub, gap=o.gap, K=K, D=D,
                                            B=B * float(ratios[i]),
                                            omega=o.omega, law=law, a0=a0, jac=self.jacs[i],
                                            settle_periods=settle)
            if not conv or not np.all(np.isfinite(xs)):
                ok = False
                res.append(np.full(2 * nh + 1, _FAIL))
                rot = float(pb.rotations[i])
                if math.isfinite(rot) and math.isfinite(float(pb.phase_widths[i])):
                    res.append(np.array([_FAIL]))
                continue
            self.states[i], self.jacs[i], self.found[i] = s, J, True
            X = np.fft.rfft(xs)[:nh + 1] * (2.0 / xs.size)
            X[0] *= 0.5
            rot, w = float(pb.rotations[i]), float(pb.phase_widths[i])
            prior = (rot, w) if math.isfinite(rot) and math.isfinite(w) else None
            phi = align_phase(X, meas.Y[i], meas.sigma[i], prior)
            self.phases[i] = phi
            d = (X * np.exp(-1j * np.arange(nh + 1) * phi) - meas.Y[i]) / meas.sigma[i]
            r = np.concatenate([[d[0].real], d[1:].real, d[1:].imag])
            res.append(np.where(np.isfinite(r), r, 0.0))
            if prior is not None:
                res.append(np.array([wrap_angle(phi - rot) / w]))
        self.ok = ok
        res.append(np.asarray(self.priors(u), float))
        return np.concatenate(res)


def _min_exponent(law: OutputErrorLaw, u: FloatArray) -> float:
    """The smallest ``delta^p`` exponent of the law at ``u`` (inf without one)."""
    ps = [float(t.p) for t in law.library_at(u).terms if isinstance(t, Indentation)]
    return min(ps, default=math.inf)


def _bounds(problem: JointProblem, law: OutputErrorLaw, u0: FloatArray
            ) -> tuple[FloatArray, FloatArray]:
    cons = problem.constraints
    lo = np.full(u0.size, -np.inf)
    hi = np.full(u0.size, np.inf)
    for idx, mean, name in ((0, 1.0, "stiffness"), (1, 1.0 / problem.quality_factor,
                                                    "damping")):
        t = cons.box(name)
        lo[idx], hi[idx] = mean * (1 - t), mean * (1 + t)
    fc = problem.drive_amplitude
    if fc is not None:
        t = cons.box("drive")
        lo[2], hi[2] = fc * (1 - t), fc * (1 + t)
    else:
        lo[2] = 0.0
    lo[3], hi[3] = problem.a0_range
    if law.exponent_index is not None:
        lo[4], hi[4] = 0.5, 4.0
    if problem.physical_signs:
        sg = np.array([t.sign for t in law.library.terms], int)
        h = law.n_head
        lo[h:][sg > 0] = 0.0
        hi[h:][sg < 0] = 0.0
    return lo, hi


def _typical(problem: JointProblem, law: OutputErrorLaw, u: FloatArray) -> FloatArray:
    """Typical magnitude of every entry of ``u``: ``|u|`` for the head (``K``, ``D``, ``B``,
    ``a0``, ``p``; the calibration values where ``u`` is 0) and, for a force coefficient, the
    larger of ``|c|`` and the value giving 1 % of the law's RMS force on the denoised orbits."""
    h = law.n_head
    out = np.abs(np.asarray(u, float)).copy()
    head = [1.0, 1.0 / problem.quality_factor, problem.drive_amplitude or 1e-3,
            float(np.mean(problem.a0_range)), 2.0][:h]
    out[:h] = np.where(out[:h] > 0, out[:h], head)
    if law.library.n_terms:
        lib = law.library_at(u)
        ins = problem.orbit_inputs(float(u[3]), offsets=False)
        th = np.concatenate([lib.evaluate(t) for t in ins])
        f_rms = float(np.sqrt(np.mean((th @ u[h:]) ** 2))) or 1e-3
        t_rms = np.sqrt(np.mean(th**2, axis=0))
        typ = np.where(t_rms > 0, 0.01 * f_rms / np.where(t_rms > 0, t_rms, 1.0), 1.0)
        out[h:] = np.maximum(out[h:], typ)
    out[~np.isfinite(out) | (out <= 0)] = 1.0
    return out


def _start(problem: JointProblem, law: OutputErrorLaw, a0: float, coef: FloatArray
           ) -> FloatArray:
    """``u`` from an equation-error solution in the joint layout."""
    n_lin = problem.n_lin
    rot = problem.rotated
    if rot.any():
        B = float(np.hypot(coef[N_LEVER], coef[N_LEVER + 1]))
    else:
        j = n_lin - 2 * int((~rot).sum())
        r_free = problem.drive_ratios[~rot]
        B = float(np.mean([np.hypot(coef[j + 2 * k], coef[j + 2 * k + 1]) / r_free[k]
                           for k in range(int((~rot).sum()))]))
    head = [-float(coef[1]), -float(coef[0]), B, float(a0)]
    if law.exponent_index is not None:
        head.append(float(law.library.terms[law.exponent_index].p))
    return np.array([*head, *np.asarray(coef[n_lin:], float)])


# ---------------------------------------------------------------------------- stages
@final
@dataclass(frozen=True)
class OutputErrorFit:
    """Refine the shared law and the drive phases against every observation's harmonics.

    Parameters
    ----------
    n_harmonics : int
        Harmonics compared per observation (capped by each record's own harmonic fit).
    n_out : int
        Kernel output samples per period (the orbit's FFT length; >= 4 n_harmonics).
    substeps : int
        RK4 steps per output sample.
    low_exponent, low_exponent_substeps : float, int
        While the law has a ``delta^p`` with ``p < low_exponent`` the period map takes
        ``max(substeps, low_exponent_substeps)`` steps per sample: the force's derivative
        ``p delta^(p-1)`` is unbounded at the onset for ``p < 1`` and the fixed-step orbit's
        error there exceeds the noise (measured on a one-amplitude series, 8 x 600 periods,
        1 % noise, 128 samples per period: chi2 at p = 0.59 off by 3.1 with 1 step, 0.2 with
        4, against 8; at p = 0.8-1.0 by 0.2-0.7 with 1 step; at p >= 1.3 by <= 0.02). A period
        costs 1.0 : 1.7 : 3.0 at 1 : 2 : 4 steps.
    max_nfev : int
        Evaluation budget of the trust-region least squares.
    diff_step : float
        Relative finite-difference step of the Jacobian (on ``u`` scaled to order one).
    """

    n_harmonics: int = 30
    n_out: int = 128
    substeps: int = 1
    max_nfev: int = 40
    diff_step: float = 1e-4
    low_exponent: float = 1.25
    low_exponent_substeps: int = 4

    def __post_init__(self) -> None:
        if not (isinstance(self.n_harmonics, int) and self.n_harmonics >= 1):
            raise ValueError(f"n_harmonics must be an integer >= 1, got {self.n_harmonics!r}")
        if not (isinstance(self.n_out, int) and self.n_out >= 4 * self.n_harmonics):
            raise ValueError(f"n_out must be an integer >= 4 n_harmonics, got {self.n_out!r}")
        if not (isinstance(self.substeps, int) and self.substeps >= 1):
            raise ValueError(f"substeps must be an integer >= 1, got {self.substeps!r}")
        if not (isinstance(self.low_exponent_substeps, int)
                and self.low_exponent_substeps >= 1):
            raise ValueError("low_exponent_substeps must be an integer >= 1, got "
                             f"{self.low_exponent_substeps!r}")
        if not (isinstance(self.max_nfev, int) and self.max_nfev >= 1):
            raise ValueError(f"max_nfev must be an integer >= 1, got {self.max_nfev!r}")

    def measure(self, problem: JointProblem) -> MeasuredHarmonics:
        return measured_harmonics(problem, self.n_harmonics)

    def solve(self, problem: JointProblem, meas: MeasuredHarmonics, law: OutputErrorLaw,
              u0: FloatArray, *, fixed: dict[int, float] | None = None,
              states: FloatArray | None = None, max_nfev: int | None = None
              ) -> tuple[OutputErrorResult, FloatArray]:
        """Least squares from ``u0`` with the entries ``fixed`` held; also the orbits' states
        (n_obs, 2) at the end (warm starts for a neighbouring fit)."""
        obj = _Objective(problem, meas, law, self.n_out, self.substeps, dict(fixed or {}),
                         (float(self.low_exponent), int(self.low_exponent_substeps)))
        if states is not None:
            obj.states = np.array(states, float)
        lo, hi = _bounds(problem, law, u0)
        u0 = np.clip(np.asarray(u0, float), lo, hi)
        mask = np.ones(u0.size, bool)
        for j in obj.fixed:
            mask[j] = False
        x0, lo_f, hi_f = u0[mask], lo[mask], hi[mask]
        # keep the start strictly inside (trf needs it)
        span = np.where(np.isfinite(hi_f - lo_f), hi_f - lo_f, 0.0)
        x0 = np.clip(x0, lo_f + 1e-9 * span, hi_f - 1e-9 * span)
        # the least squares runs on u / scale (entries of order one): scipy's finite
        # difference step is relative to max(1, |x|), i.e. absolute for small parameters
        scale = _typical(problem, law, u0)[mask]
        r0 = obj(x0)
        if not obj.ok:  # the start's orbits cannot be found: nothing to refine
            cov = np.full((u0.size, u0.size), np.nan)
            return (OutputErrorResult(law=law, u=obj.full(x0), phases=obj.phases.copy(),
                                      chi2=math.inf, dof=1, converged=False, covariance=cov),
                    obj.states.copy())
        fit = least_squares(lambda v: obj(v * scale), x0 / scale,
                            bounds=(lo_f / scale, hi_f / scale), diff_step=self.diff_step,
                            method="trf", max_nfev=max_nfev or self.max_nfev, xtol=1e-8,
                            ftol=1e-6)
        x = fit.x * scale if float(fit.cost) <= 0.5 * float(r0 @ r0) else x0
        r = obj(x)
        chi2 = float(r @ r)
        n_res = int(np.sum(r != 0.0))
        dof = max(n_res - int(mask.sum()) - problem.n_obs, 1)
        cov = np.full((u0.size, u0.size), np.nan)
        try:
            Jm = fit.jac / scale
            c = np.linalg.pinv(Jm.T @ Jm) * max(1.0, chi2 / dof)
            idx = np.flatnonzero(mask)
            cov[np.ix_(idx, idx)] = c
        except (np.linalg.LinAlgError, ValueError):
            pass
        res = OutputErrorResult(law=law, u=obj.full(x), phases=obj.phases.copy(), chi2=chi2,
                                dof=dof, converged=obj.ok, covariance=cov, nfev=int(fit.nfev))
        return res, obj.states.copy()

    def run(self, problem: JointProblem, library: AFMLibrary, a0: float, coef: FloatArray,
            exponent: float | None) -> tuple[OutputErrorResult, MeasuredHarmonics]:
        """Refine the equation-error solution ``(library, a0, coef)`` (joint layout).

        ``exponent``: the dominant ``delta^p`` term's exponent (fitted too), or None.
        """
        idx = None
        if exponent is not None:
            js = [j for j, t in enumerate(library.terms)
                  if isinstance(t, Indentation) and t.p == exponent]
            idx = js[0] if js else None
        law = OutputErrorLaw(library=library, exponent_index=idx)
        meas = self.measure(problem)
        res, _ = self.solve(problem, meas, law, _start(problem, law, a0, coef))
        return res, meas


@final
@dataclass(frozen=True)
class OutputErrorProfile:
    """Profile likelihood of the contact exponent over the output-error objective.

    From the fitted exponent outwards in ``step`` increments (each point re-optimises every
    other parameter from its neighbour's solution) until ``chi2`` exceeds the 95 % level by
    a margin or the range ``[low, high]`` ends; the interval's ends are interpolated
    linearly in ``sqrt(chi2 - chi2_min)`` (exact for a quadratic profile). The level is
    ``3.841 * max(1, chi2_min / dof)`` (quasi-likelihood: a law that cannot fit every orbit
    to the noise widens the interval). ``bounded`` is False when the interval reaches
    ``low`` or ``high``. A lower minimum found along the way moves the estimate there (the
    start was a local minimum).

    A profile point is only an upper bound of the profile (its fit may end in another basin
    of ``a0``; measured on the two-amplitude benchmark series: points 4-2,700 chi2 above both
    neighbours, walks stopped at them). So a point where the walk would stop is retried from
    its neighbour with fresh orbit states (:meth:`_retry`); after the walk, every point above
    the chord of its neighbours by ``polish_tol`` is re-solved from the lower neighbour
    (:meth:`_polish`); with ``refine``, points half a step either side of the lowest one are
    added and the estimate is the vertex of the parabola through the lowest point and its two
    neighbours (re-fitted there; the free-exponent fit from it is kept only when it is lower
    and stays between the neighbours), not wherever a free fit stopped in a flat valley.
    """

    low: float = 0.5
    high: float = 4.0
    step: float = 0.2
    max_points: int = 20
    max_nfev: int = 30
    restart_nfev: int = 8
    polish_tol: float = 0.5
    refine: bool = True

    def _walk(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
              start: OutputErrorResult, restarts: Restarts | None = None
              ) -> dict[float, OutputErrorResult]:
        """One law's profile: the grid ``low + k step`` from ``start``'s exponent outwards.

        Every point starts from its neighbour's solution and, with ``restarts``, also from
        each start ``restarts(law, u, p)`` (``restart_nfev`` evaluations each; the best one
        is then converged): ``a0`` moves far along the exponent's valley, from one basin to
        another, which a warm start alone does not follow (measured: profile points 5-8
        chi2 above the fixed-exponent optimum, a jagged profile)."""
        ei = start.law.exponent_index
        assert ei is not None
        grid = np.round(np.arange(self.low, self.high + 1e-9, self.step), 6)
        p0 = float(start.u[4])
        pts: dict[float, OutputErrorResult] = {round(p0, 6): start}
        level = 3.841 * start.dispersion
        n = 0
        for side in (grid[grid < p0 - 1e-6][::-1], grid[grid > p0 + 1e-6]):
            prev, states = start, None
            for p in side:
                if n >= self.max_points:
                    break
                u0 = prev.u.copy()
                # the contact coefficient rescaled to keep the force at the deepest
                # indentation: a start near the new exponent's optimum
                depth = max(float(prev.u[3]) - problem.z_min(), 1e-6)
                u0[start.law.n_head + ei] *= depth ** (float(prev.u[4]) - p)
                u0[4] = p
                r, states = fit.solve(problem, meas, start.law, u0, fixed={4: float(p)},
                                      states=states, max_nfev=self.max_nfev)
                if restarts is not None:
                    alt = None
                    for ua in restarts(start.law, prev.u, float(p)):
                        ra, _ = fit.solve(problem, meas, start.law, ua, fixed={4: float(p)},
                                          max_nfev=self.restart_nfev)
                        if ra.converged and ra.chi2 < min(r.chi2, math.inf if alt is None
                                                         else alt.chi2):
                            alt = ra
                    if alt is not None:
                        ra, sa = fit.solve(problem, meas, start.law, alt.u,
                                           fixed={4: float(p)}, max_nfev=self.max_nfev)
                        if ra.converged and ra.chi2 < r.chi2:
                            r, states = ra, sa
                n += 1
                if r.chi2 - min(v.chi2 for v in pts.values()) > level + 2.0:
                    # about to stop: make sure it is the profile, not a lost basin
                    r = self._retry(fit, problem, meas, prev, float(p), r)
                pts[float(p)] = r
                if math.isfinite(r.chi2):
                    prev = r
                if r.chi2 - min(v.chi2 for v in pts.values()) > level + 2.0:
                    break
        return self._polish(fit, problem, meas, pts, level)

    def _from(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
              src: OutputErrorResult, p: float, *, rescale: bool = True
              ) -> OutputErrorResult:
        """The fit at fixed exponent ``p`` started from ``src`` (fresh orbit states), the
        contact coefficient rescaled to keep the force at the deepest indentation."""
        ei = src.law.exponent_index
        assert ei is not None
        u0 = src.u.copy()
        if rescale:
            depth = max(float(src.u[3]) - problem.z_min(), 1e-6)
            u0[src.law.n_head + ei] *= depth ** (float(src.u[4]) - p)
        u0[4] = p
        r, _ = fit.solve(problem, meas, src.law, u0, fixed={4: float(p)},
                         max_nfev=self.max_nfev)
        return r

    def _retry(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
               prev: OutputErrorResult, p: float, r: OutputErrorResult) -> OutputErrorResult:
        """The better of ``r`` and fits at ``p`` from ``prev`` with fresh orbit states (the
        contact coefficient rescaled or not): a warm-started orbit can jump to the other
        branch of the tapping orbit."""
        for rescale in (True, False):
            ra = self._from(fit, problem, meas, prev, p, rescale=rescale)
            if ra.converged and ra.chi2 < r.chi2:
                r = ra
        return r

    def _polish(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
                pts: dict[float, OutputErrorResult], level: float
                ) -> dict[float, OutputErrorResult]:
        """Re-solve every point above the chord of its two neighbours by ``polish_tol``
        (within ``4 level`` of the minimum) from its lower neighbour; two passes each way."""
        pts = dict(pts)
        for _ in range(2):
            changed = False
            for ks in (sorted(pts), sorted(pts)[::-1]):
                for i in range(1, len(ks) - 1):
                    a, k, b = pts[ks[i - 1]], pts[ks[i]], pts[ks[i + 1]]
                    c_min = min(v.chi2 for v in pts.values())
                    if not math.isfinite(c_min) or (math.isfinite(k.chi2)
                                                    and k.chi2 - c_min > 4 * level + 2.0):
                        continue
                    w = (ks[i + 1] - ks[i]) / (ks[i + 1] - ks[i - 1])
                    chord = w * a.chi2 + (1 - w) * b.chi2
                    if not (k.chi2 > chord + self.polish_tol):
                        continue
                    src = a if a.chi2 <= b.chi2 else b
                    if not math.isfinite(src.chi2):
                        continue
                    r = self._from(fit, problem, meas, src, float(ks[i]))
                    if r.converged and r.chi2 < k.chi2:
                        pts[ks[i]] = r
                        changed = True
            if not changed:
                break
        return pts

    def run(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
            starts: list[OutputErrorResult],
            points: dict[float, OutputErrorResult] | None = None,
            restarts: Restarts | None = None
            ) -> tuple[dict[str, Any], OutputErrorResult]:
        """The profile table and interval over the laws of ``starts`` (each with a contact
        exponent), and the best solution found.

        Each law is profiled on its own; the profile of the exponent is their lower envelope
        in ``chi2 + n_u log(n_residuals)`` (the laws may differ in their number of terms), and
        a profile point better than every start is re-fitted with the exponent free.
        ``points``: further fixed-exponent fits (e.g. a scan's), merged into the envelope.
        The table's ``fits`` maps every profiled exponent to its fit (the law quoted at a
        fixed exponent when the data do not bound it: :mod:`afmlearn.identify.fixed_exponent`).
        """
        starts = [r for r in starts if r.law.exponent_index is not None]
        assert starts
        env: dict[float, tuple[float, OutputErrorResult]] = {}
        walks = [self._walk(fit, problem, meas, st, restarts) for st in starts]
        for pts in [*walks, dict(points or {})]:
            for p, r in pts.items():
                p = round(float(p), 6)
                sc = _bic(r)
                if math.isfinite(sc) and (p not in env or sc < env[p][0]):
                    env[p] = (sc, r)
        best = min(starts, key=_bic)
        self._polish_envelope(fit, problem, meas, env, 3.841 * best.dispersion)
        if self.refine:
            best = self._vertex(fit, problem, meas, env, best)
        else:
            k_min = min(env, key=lambda k: env[k][0])
            if env[k_min][0] < _bic(best) - 1e-6 * max(best.chi2, 1.0):
                # a better basin along a profile: free the exponent again from there
                cand = env[k_min][1]
                better, _ = fit.solve(problem, meas, cand.law, cand.u)
                best = better if better.converged and _bic(better) < env[k_min][0] else cand
                p_b = round(float(best.u[4]), 6)
                if p_b not in env or _bic(best) < env[p_b][0]:
                    env[p_b] = (_bic(best), best)
        ks = sorted(env)
        prof = np.array([(k, env[k][0]) for k in ks])
        level = 3.841 * best.dispersion
        lo, hi, crossed = _crossings(prof, level)
        # bounded: both ends strictly inside the walk's grid (an end at its last point, or
        # beyond it at a scan's or the estimate's exponent, is the range's end)
        top = self.low + self.step * math.floor((self.high - self.low) / self.step + 1e-9)
        bounded = bool(crossed and lo > self.low + 1e-6 and hi < top - 1e-6)
        # "n_rows": the count for which n log(score / score_min) ~ (score - score_min) /
        # dispersion, the equation-error profile's statistic (what the figures draw)
        n_eq = float(np.nanmin(prof[:, 1])) / best.dispersion
        return ({"profile": prof, "interval": (lo, hi), "bounded": bounded,
                 "best_exponent": float(best.u[4]), "level": level,
                 "dispersion": best.dispersion, "objective": "output_error",
                 "n_rows": n_eq, "laws": [r.law.library.names for r in starts],
                 "fits": {k: env[k][1] for k in ks}}, best)

    def _polish_envelope(self, fit: OutputErrorFit, problem: JointProblem,
                         meas: MeasuredHarmonics,
                         env: dict[float, tuple[float, OutputErrorResult]], level: float
                         ) -> None:
        """Re-solve (in place) every point of the laws' envelope that lies above the chord of
        its two neighbours by more than ``level``, from the lower neighbour's fit (that law):
        a walk's start or a scan point that ended in another basin is not the profile
        (measured: the baseline law's start at p = 1.44, 28 chi2 above both neighbours on a
        one-amplitude series, cut the interval at 1.31 instead of about 1.5)."""
        for ks in (sorted(env), sorted(env)[::-1]):
            for i in range(1, len(ks) - 1):
                (sa, a), (sk, _), (sb, b) = env[ks[i - 1]], env[ks[i]], env[ks[i + 1]]
                w = (ks[i + 1] - ks[i]) / (ks[i + 1] - ks[i - 1])
                if not sk > w * sa + (1 - w) * sb + level:
                    continue
                r = self._from(fit, problem, meas, a if sa <= sb else b, float(ks[i]))
                if r.converged and _bic(r) < sk:
                    env[ks[i]] = (_bic(r), r)

    def _vertex(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
                env: dict[float, tuple[float, OutputErrorResult]], best: OutputErrorResult
                ) -> OutputErrorResult:
        """The estimate at the profile's minimum (``env``: exponent -> (BIC, fit), updated).

        Points half a step either side of the lowest one (fixed-exponent fits from it), then
        the vertex of the parabola through the lowest point and its neighbours, fitted at that
        exponent; a free-exponent fit from there replaces it only when lower and between the
        neighbours. Returns the fit with the lowest BIC found."""

        def add(r: OutputErrorResult) -> None:
            if r.converged and math.isfinite(r.chi2):
                p = round(float(r.u[4]), 6)
                if p not in env or _bic(r) < env[p][0]:
                    env[p] = (_bic(r), r)

        add(best)
        for _ in range(2):  # the lowest point may move to a new half-step point once
            k_min = min(env, key=lambda k: env[k][0])
            cand = env[k_min][1]
            for p in (round(k_min - self.step / 2, 6), round(k_min + self.step / 2, 6)):
                if (self.low - 1e-9 <= p <= self.high + 1e-9
                        and min(abs(k - p) for k in env) > self.step / 8):
                    add(self._from(fit, problem, meas, cand, float(p)))
            if min(env, key=lambda k: env[k][0]) == k_min:
                break
        ks = sorted(env)
        k_min = min(env, key=lambda k: env[k][0])
        i = ks.index(k_min)
        cand = env[k_min][1]
        if 0 < i < len(ks) - 1:
            trio = ks[i - 1:i + 2]
            pv = _vertex_of(np.array(trio), np.array([env[k][0] for k in trio]))
            if pv is not None and min(abs(k - pv) for k in trio) > 1e-3:
                near = min(trio, key=lambda k: (abs(k - pv), env[k][0]))
                k_v = round(pv, 6)
                add(self._from(fit, problem, meas, env[near][1], k_v))
                if k_v in env and env[k_v][0] < env[k_min][0] + self.polish_tol:
                    cand = env[k_v][1]
            free, _ = fit.solve(problem, meas, cand.law, cand.u)
            if (free.converged and _bic(free) < min(v[0] for v in env.values())
                    and trio[0] < float(free.u[4]) < trio[2]):
                add(free)
                cand = free
        return cand


def _vertex_of(ps: FloatArray, cs: FloatArray) -> float | None:
    """Abscissa of the minimum of the parabola through three points (None when it is not
    convex); clipped to the outer two abscissae."""
    (p0, p1, p2), (c0, c1, c2) = ps, cs
    den = (p0 - p1) * (p0 - p2) * (p1 - p2)
    if den == 0.0:
        return None
    a = (p2 * (c1 - c0) + p1 * (c0 - c2) + p0 * (c2 - c1)) / den
    b = (p2 * p2 * (c0 - c1) + p1 * p1 * (c2 - c0) + p0 * p0 * (c1 - c2)) / den
    if not (a > 0.0 and math.isfinite(b)):
        return None
    return float(min(max(-b / (2.0 * a), p0), p2))


def _crossings(prof: FloatArray, level: float) -> tuple[float, float, bool]:
    """Where ``chi2 - min`` last rises above ``level`` on either side of the minimum, and
    whether it does on both sides (else that end is the profile's end).

    Interpolated linearly in ``sqrt(chi2 - min)``, which is linear in the parameter for a
    quadratic profile (so a coarse grid does not shrink the interval). Every point at or below
    the level lies inside (a profile with two dips gives the hull).
    """
    p, c = prof[:, 0], prof[:, 1]
    ok = np.isfinite(c)
    p, c = p[ok], np.sqrt(np.maximum(c[ok] - np.min(c[ok]), 0.0))
    t = math.sqrt(level)
    inside = np.flatnonzero(c <= t)
    a, b = int(inside.min()), int(inside.max())
    lo, hi = float(p[a]), float(p[b])
    if a > 0:
        lo = float(p[a] + (t - c[a]) / (c[a - 1] - c[a]) * (p[a - 1] - p[a]))
    if b < p.size - 1:
        hi = float(p[b] + (t - c[b]) / (c[b + 1] - c[b]) * (p[b + 1] - p[b]))
    return lo, hi, bool(a > 0 and b < p.size - 1)


# ---------------------------------------------------------------------------- support
def _bic(r: OutputErrorResult) -> float:
    """``chi2 + n_u log(n_res)`` (Schwarz's criterion for Gaussian residuals of known noise)."""
    return r.chi2 + r.u.size * math.log(max(r.dof + r.u.size, 2))


def _small(problem: JointProblem, res: OutputErrorResult, terms: list[Any]) -> FloatArray:
    """Start coefficients of added ``terms``: 5 % of the law's RMS force on the denoised
    orbits each, with the term's physical sign (a start ON a sign bound can stay there)."""
    lib, a0, c = res.library, res.a0, res.u[res.law.n_head:]
    ins = problem.orbit_inputs(a0, offsets=False)
    f_rms = float(np.sqrt(np.mean(np.concatenate([lib.evaluate(t) @ c for t in ins]) ** 2)))
    extra = AFMLibrary(list(terms))
    t_rms = np.sqrt(np.mean(np.concatenate([extra.evaluate(t) for t in ins]) ** 2, axis=0))
    sign = np.array([t.sign if problem.physical_signs and t.sign else 1 for t in terms], float)
    return np.where(t_rms > 0, sign * 0.05 * f_rms / np.where(t_rms > 0, t_rms, 1.0), 0.0)


@final
@dataclass(frozen=True)
class OutputErrorSupport:
    """Which force terms the output-error law keeps: one term at a time, by BIC on ``chi2``.

    The equation-error selection ranks the terms (its forward path) but judges them on rows
    whose denoised orbit is wrong near the turning point, where it buys ``x^k`` or damping
    terms in place of the contact law. Here the support is revised on the output-error
    objective: up to ``max_add`` terms that entered the forward path after the chosen support
    are tried one at a time (kept if the BIC falls), then every term but the dominant contact
    term is tried for removal (dropped while the BIC falls).
    """

    max_add: int = 3
    max_nfev: int = 40

    def run(self, fit: OutputErrorFit, problem: JointProblem, meas: MeasuredHarmonics,
            base: OutputErrorResult, extra: list[Any]) -> OutputErrorResult:
        """``extra``: candidate additions, each a term or a tuple of terms entered together."""
        best = base
        tried = 0
        for cand in extra:
            if tried >= self.max_add:
                break
            group = list(cand) if isinstance(cand, tuple) else [cand]
            names = {t.name for t in best.law.library.terms}
            group = [t for t in group if t.name not in names]
            if not group:
                continue
            tried += 1
            lib = AFMLibrary([*best.law.library.terms, *group])
            law = OutputErrorLaw(library=lib, exponent_index=best.law.exponent_index)
            r, _ = fit.solve(problem, meas, law, np.append(best.u, _small(problem, best, group)),
                             max_nfev=self.max_nfev)
            if r.converged and _bic(r) < _bic(best):
                best = r
        changed = True
        while changed and best.law.library.n_terms > 1:
            changed = False
            h = best.law.n_head
            trials = []
            for j in range(best.law.library.n_terms):
                if j == best.law.exponent_index:
                    continue
                keep = np.ones(best.law.library.n_terms, bool)
                keep[j] = False
                ei = best.law.exponent_index
                law = OutputErrorLaw(library=best.law.library.subset(keep),
                                     exponent_index=None if ei is None else ei - (j < ei))
                u0 = np.concatenate([best.u[:h], best.u[h:][keep]])
                r, _ = fit.solve(problem, meas, law, u0, max_nfev=self.max_nfev)
                if r.converged:
                    trials.append(r)
            if trials:
                r = min(trials, key=_bic)
                if _bic(r) < _bic(best):
                    best, changed = r, True
        return best


# ---------------------------------------------------------------------------- the stage
@final
@dataclass(frozen=True)
class OutputErrorStage:
    """The joint fit's output-error stage: refine, revise the support, profile the exponent.

    ``run`` takes the equation-error solution and returns the output-error one (or None when
    its orbits cannot be found: the caller keeps the equation-error law) and the exponent's
    profile over the output-error objective (None without a contact term). Order: refine from
    the equation-error law; restart from ``n_onsets`` contact onsets spread over the allowed
    range (geometric, the ends excluded) and keep the best; the baseline law from a coarse
    scan over exponents and onsets (:meth:`_scan`); revise the support; profile both laws.
    """

    fit: OutputErrorFit = field(default_factory=OutputErrorFit)
    support: OutputErrorSupport | None = field(default_factory=OutputErrorSupport)
    profile: OutputErrorProfile | None = field(default_factory=OutputErrorProfile)
    n_onsets: int = 5
    onset_nfev: int = 25
    scan_exponents: tuple[float, ...] = (1.0, 1.5, 2.0, 2.5, 3.0)
    scan_nfev: int = 8
    #: every profile point also starts from the ``n_onsets`` onsets (:meth:`_onset_starts`)
    profile_restarts: bool = True

    def run(self, problem: JointProblem, library: AFMLibrary, a0: float, coef: FloatArray,
            exponent: float | None, extra: list[Any] | None = None,
            baseline: list[Any] | None = None,
            linear: Callable[[AFMLibrary, float], FloatArray] | None = None
            ) -> tuple[OutputErrorResult | None, dict[str, Any] | None]:
        """``extra``: candidate terms for the support revision; ``baseline``: terms that with
        the dominant contact term alone form a second starting law (the physics.md baseline:
        the sphere's van der Waals ``z^-2``), started from a scan (:meth:`_scan`); both laws
        are profiled. ``linear(library, a0)``: force coefficients of ``library`` at ``a0``
        by the equation-error fit (joint layout; the scan's coordinated starts)."""
        res, meas = self.fit.run(problem, library, a0, coef, exponent)
        if not res.converged or not math.isfinite(res.chi2):
            res = self._restart(problem, meas, res)
        if not res.converged or not math.isfinite(res.chi2):
            return None, None
        res = self._onsets(problem, meas, res)
        ei = res.law.exponent_index
        laws = []
        points: dict[float, OutputErrorResult] = {}
        if baseline and ei is not None:
            h = res.law.n_head
            law_b = OutputErrorLaw(library=AFMLibrary([res.law.library.terms[ei], *baseline]),
                                   exponent_index=0)
            if set(law_b.library.names) != set(res.law.library.names):
                u_b = np.concatenate([res.u[:h], [res.u[h + ei]],
                                      _small(problem, res, baseline)])
                rb = self._scan(problem, meas, law_b, u_b, linear, points)
                if rb is not None:
                    laws.append(rb)
        if self.support is not None:
            res = self.support.run(self.fit, problem, meas, res, list(extra or []))
        laws = [res, *(r for r in laws
                       if set(r.law.library.names) != set(res.law.library.names))]
        expo = None
        if self.profile is not None and res.law.exponent_index is not None:
            restarts = None
            if self.profile_restarts:
                def restarts(law: OutputErrorLaw, u: FloatArray, p: float) -> list[FloatArray]:
                    return self._onset_starts(problem, law, u, p, linear)
            expo, res = self.profile.run(self.fit, problem, meas, laws, points,
                                         restarts=restarts)
            assert res.law.exponent_index is not None
            expo["term_index"] = int(res.law.exponent_index)
            expo["cv_interval"] = (math.nan, math.nan)
            expo["cv_bounded"] = False
        else:
            res = min(laws, key=_bic)
        return res, expo


    def _scan(self, problem: JointProblem, meas: MeasuredHarmonics, law: OutputErrorLaw,
              u: FloatArray, linear: Callable[[AFMLibrary, float], FloatArray] | None,
              points: dict[float, OutputErrorResult]) -> OutputErrorResult | None:
        """A coarse global start for ``law`` (contact exponent at index 0 of its terms): the
        exponents ``scan_exponents`` x the contact onsets of :meth:`_onsets`, each a short fit
        at fixed exponent (the contact coefficient rescaled to keep the force at the deepest
        indentation, the other coefficients at ``u``); the best, re-fitted with everything
        free. The sphere's adhesion and ``a0`` trade with the exponent along a valley that a
        local fit from a steeper law's estimate does not cross (measured on the benchmark's
        DMT series: it ended at ``p`` 2.1 with no adhesion, 4.6 chi² above the true law).
        With ``linear`` the coefficients of every start come from the equation-error fit at
        its ``(p, a0)``. Each scanned exponent's best fit, converged at that exponent, is
        stored in ``points`` (profile points)."""
        best: OutputErrorResult | None = None
        for p in self.scan_exponents:
            best_p: OutputErrorResult | None = None
            for u0 in self._onset_starts(problem, law, u, float(p), linear):
                r, _ = self.fit.solve(problem, meas, law, u0, fixed={4: float(p)},
                                      max_nfev=self.scan_nfev)
                if r.converged and (best_p is None or r.chi2 < best_p.chi2):
                    best_p = r
            if best_p is None:
                continue
            # the exponent's best basin, converged: a point of its profile (any fixed-p fit
            # bounds the profile from above; a walk from one basin can miss another)
            r, _ = self.fit.solve(problem, meas, law, best_p.u, fixed={4: float(p)})
            best_p = r if r.converged and r.chi2 <= best_p.chi2 else best_p
            points[float(p)] = best_p
            if best is None or best_p.chi2 < best.chi2:
                best = best_p
        if best is None:
            return None
        r, _ = self.fit.solve(problem, meas, law, best.u)
        return r if r.converged and r.chi2 <= best.chi2 else best

    def _onset_starts(self, problem: JointProblem, law: OutputErrorLaw, u: FloatArray,
                      p: float, linear: Callable[[AFMLibrary, float], FloatArray] | None
                      ) -> list[FloatArray]:
        """Starts of a fit at exponent ``p``: ``u`` with ``a0`` at each of the
        ``n_onsets`` contact onsets, the contact coefficient rescaled to keep the force at the
        deepest indentation and, with ``linear``, every force coefficient from the
        equation-error fit at that ``(p, a0)``."""
        ei = law.exponent_index
        assert ei is not None
        lo, hi = problem.a0_range
        zmin = problem.z_min()
        h = law.n_head
        d0 = max(float(u[3]) - zmin, 1e-6)
        out = []
        for a in np.geomspace(lo, hi, self.n_onsets + 2)[1:-1]:
            u0 = np.array(u, float)
            u0[3], u0[4] = a, p
            u0[h + ei] = u[h + ei] * d0 ** float(u[4]) / max(a - zmin, 1e-6) ** p
            if linear is not None:
                # the coefficients coordinated with (p, a0) by the linear rows: the orbit
                # is so sensitive to the adhesion that an uncoordinated start falls into
                # another basin (measured: half the true z^-2 raised chi2 40-fold)
                c = np.asarray(linear(law.library_at(u0), float(a)), float)
                c = c[problem.n_lin:]
                if c.size == law.library.n_terms and np.all(np.isfinite(c)):
                    u0[h:] = c
            out.append(u0)
        return out

    def _onsets(self, problem: JointProblem, meas: MeasuredHarmonics,
                res: OutputErrorResult) -> OutputErrorResult:
        """Starts at ``n_onsets`` contact onsets across the allowed range; the best fit.

        ``a0`` and the exponent trade along a valley with more than one basin (measured: the
        equation-error start at 4x the true ``a0`` converged there, 90 chi2 units above the
        true law's basin); every start keeps the contact force at the deepest indentation
        (its coefficient rescaled)."""
        if self.n_onsets <= 0:
            return res
        lo, hi = problem.a0_range
        zmin = problem.z_min()
        h = res.law.n_head
        ei = res.law.exponent_index
        best = res
        for a in np.geomspace(lo, hi, self.n_onsets + 2)[1:-1]:
            if abs(math.log(a / res.a0)) < 0.2:
                continue
            u0 = res.u.copy()
            u0[3] = a
            if ei is not None:
                d_old, d_new = max(res.a0 - zmin, 1e-6), max(a - zmin, 1e-6)
                u0[h + ei] *= (d_old / d_new) ** float(res.u[4])
            r, _ = self.fit.solve(problem, meas, res.law, u0, max_nfev=self.onset_nfev)
            if r.converged and r.chi2 < best.chi2:
                best = r
        if best is not res:
            best, _ = self.fit.solve(problem, meas, best.law, best.u)
        return best

    def _restart(self, problem: JointProblem, meas: MeasuredHarmonics,
                 failed: OutputErrorResult) -> OutputErrorResult:
        """Starts with one other force term (or all of them) set to zero, when some orbit of
        the equation-error law is not found (measured: a force jump at ``a0`` whose light
        tapping orbits graze it); the best converged one, or ``failed``."""
        law, u = failed.law, failed.u
        h = law.n_head
        others = [j for j in range(law.library.n_terms) if j != law.exponent_index]
        starts = [[j] for j in others] + ([others] if len(others) > 1 else [])
        best = failed
        for zero in starts:
            u0 = u.copy()
            u0[[h + j for j in zero]] = 0.0
            r, _ = self.fit.solve(problem, meas, law, u0)
            if r.converged and (not best.converged or r.chi2 < best.chi2):
                best = r
        return best


def covariance_samples(res: OutputErrorResult, problem: JointProblem, n: int, seed: int
                       ) -> FloatArray:
    """``n`` coefficient vectors (joint layout) drawn from the Gauss--Newton covariance of
    the force coefficients (shape (n, n_lin + n_terms); empty when it is not finite)."""
    coef = res.coef(problem)
    h = res.law.n_head
    cov = res.covariance[h:, h:]
    if n <= 0 or not np.all(np.isfinite(cov)):
        return np.empty((0, coef.size))
    rng = np.random.default_rng(seed)
    out = np.tile(coef, (n, 1))
    out[:, problem.n_lin:] = rng.multivariate_normal(res.u[h:], cov, size=n,
                                                     check_valid="ignore")
    return out
