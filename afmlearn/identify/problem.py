"""The joint identification problem: every observation of an experiment, one force law.

An experiment (``afmlearn.io.Experiment``: steady records at several set-points sharing the
cantilever and the tip--sample law) becomes ONE regression

    rows of observation i:  [x'']_i = -D [x']_i - K [x]_i + drive_i - sum_j c_j [theta_j]_i

with the lever's ``K``, ``D`` and the force coefficients ``c_j`` (and ``a0``, exponents)
shared, and the drive's phase per observation (each row starts at its own drive phase).
Lengths are in ONE unit for all observations, the mean rest gap ``L_ref``, so a coefficient
means the same force in every row. The rows of each observation are the harmonic balance of its
own denoised orbit (:class:`~afmlearn.identify.projection.HarmonicBalance`), divided by that
observation's own row noise (``sigma_x sqrt(2 / samples per block)``: the whitened residual of a
harmonic, since the rows are weighted by the inverse lever transfer function), so that an
observation counts by its information, not by its amplitude.

Everything here is immutable: :class:`JointProblem` is built once by :func:`build_problem`;
drive rotations or a noise scale give a NEW problem (:meth:`JointProblem.with_drive`,
:meth:`JointProblem.with_noise`); :meth:`JointProblem.design` is a pure function of
``(library, a0)``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io import Trace
from afmlearn.preprocess import (
    Calibrated,
    HarmonicFit,
    calibrate,
    check_trace,
    fit_harmonics,
)

from .constraints import CalibrationConstraints
from .library import AFMLibrary, TermInput
from .optimizers import BoxSR3
from .projection import Bound, Denoised, HarmonicBalance, RegressionData

__all__ = ["Observation", "JointDesign", "JointProblem", "build_problem", "observations_of"]

FloatArray = NDArray[np.float64]

#: the two lever columns shared by every observation
N_LEVER = 2
#: relative spread below which the observations' calibrated drives count as one drive
DRIVE_RATIO_TOL = 1e-3


@final
@dataclass(frozen=True, eq=False)
class Observation:
    """One steady record in the experiment's common units (lengths / ``L_ref``).

    Attributes
    ----------
    tau : ndarray, shape (n,)
        ``omega0 t`` from the record's first sample.
    x : ndarray, shape (n,)
        Measured deflection / L_ref.
    gap : float
        Rest gap / L_ref.
    omega : float
        Drive frequency / f0.
    drive_amplitude : float or None
        ``F_c`` [k L_ref] from the free data (None: not calibrated).
    recorded_phase : float or None
        ``phi`` [rad] of the drive ``B cos(Omega tau - phi)`` from the file's
        ``drive_phase_rad`` (``phi = -drive_phase_rad``); None when not recorded.
    denoised : Denoised
        Fourier-series state of the record (all periods).
    bound : Bound
        Its harmonic-balance rows.
    row_sigma : float
        Noise standard deviation of one of its (unwhitened) rows.
    orbit_sigma : float
        Uncertainty of the denoised orbit's gap near its turning point (/ L_ref): the prior
        width of the observation's gap offset.
    calibrated : Calibrated
        The record's own calibration (its own ``L_ref``; for SI outputs).
    """

    tau: FloatArray
    x: FloatArray
    gap: float
    omega: float
    drive_amplitude: float | None
    recorded_phase: float | None
    denoised: Denoised
    bound: Bound
    row_sigma: float
    orbit_sigma: float
    calibrated: Calibrated

    @property
    def harmonic_fit(self) -> HarmonicFit:
        hf = self.denoised.harmonic_fit
        assert hf is not None
        return hf


#: fewest samples of :meth:`JointProblem.orbit_inputs` (whole periods of the denoised orbit)
ORBIT_SAMPLES = 4096


def _whole_periods(o: Observation) -> int:
    """Samples in the fewest whole drive periods of ``o`` that hold `ORBIT_SAMPLES` (capped
    at the record)."""
    n = int(o.denoised.x.size)
    spp = 2.0 * math.pi / (o.omega * float(o.tau[1] - o.tau[0]))
    m = int(round(math.ceil(ORBIT_SAMPLES / spp - 1e-6) * spp))
    return n if m >= n else max(m, 1)


@final
@dataclass(frozen=True, eq=False)
class JointDesign:
    """Whitened joint rows of one ``(library, a0)`` and the optimizer's boxes.

    Attributes
    ----------
    theta : ndarray, shape (r, n_lin + n_terms)
        Columns ``[x', x, drive columns..., -theta_j...]``.
    y : ndarray, shape (r,)
        ``[x'']`` rows.
    lower, upper : ndarray, shape (n_lin + n_terms,)
        Boxes.
    pattern : ndarray, shape (n_lin + n_terms,)
        Per-column threshold pattern (1 / RMS of a term on the orbits; 0 for the lever and
        drive columns).
    library : AFMLibrary
    a0 : float
    """

    theta: FloatArray
    y: FloatArray
    lower: FloatArray
    upper: FloatArray
    pattern: FloatArray
    library: AFMLibrary
    a0: float

    def optimizer(self, threshold: float = 1e-300, nu: float = 1.0) -> BoxSR3:
        """A BoxSR3 with this design's boxes and per-term thresholds."""
        t = max(float(threshold), 1e-300)
        return BoxSR3(threshold=t, nu=nu, thresholds=t * self.pattern, lower=self.lower,
                      upper=self.upper, normalize_columns=True, max_iter=250, tol=1e-9,
                      unbias=True)


@final
@dataclass(frozen=True, eq=False)
class JointProblem:
    """All observations of an experiment, bound to their rows; immutable.

    Attributes
    ----------
    observations : tuple of Observation
    quality_factor : float
    constraints : CalibrationConstraints
    drive_source : str
        Where ``F_c`` comes from (calibration's ``drive_source``).
    rotations : ndarray, shape (n_obs,)
        Drive phase ``phi_i`` each observation's drive columns are rotated to (NaN: its drive
        is free, two unconstrained columns ``cos``, ``sin``).
    phase_widths : ndarray, shape (n_obs,)
        Prior width [rad] of the drive phase about ``rotations`` (inf: box only, no prior).
    noise_scale : float
        Variance of a whitened row (1 when the row noise estimates are right; set from a
        dense fit by :meth:`with_noise`), the unit of the calibration priors.
    physical_signs : bool
        Bound the force coefficients' signs (``AbstractTerm.sign``).
    a0_range : (float, float)
        Allowed contact onset (/ L_ref).
    n_blocks : int
        Row blocks (rolling cross-validation); block ``b`` holds block ``b`` of every
        observation.
    length_m : float
        ``L_ref`` [m] (mean rest gap of the observations).
    fold_by_observation : bool
        Cross-validation folds are whole observations (``blocks``): set by
        :func:`build_problem` for three or more observations, so that selection is judged on
        set-points it never fitted (a misfit that recurs in every block of an observation
        cannot pass for a law there).
    offsets : ndarray, shape (n_obs,)
        Per-observation gap offsets (/ L_ref) added to the denoised orbit's gap in the force
        terms: the orbit near its turning point is known only to ``orbit_sigma`` (noise and
        truncation of the Fourier series), and a contact force is so steep there that this
        error, different in every observation, would otherwise make the observations
        disagree about one law (errors in the variables). Gaussian prior ``N(0,
        orbit_sigma^2)``.
    """

    observations: tuple[Observation, ...]
    quality_factor: float
    constraints: CalibrationConstraints
    drive_source: str
    rotations: FloatArray
    phase_widths: FloatArray
    noise_scale: float
    physical_signs: bool
    a0_range: tuple[float, float]
    n_blocks: int
    length_m: float
    offsets: FloatArray
    fold_by_observation: bool = False

    # ------------------------------------------------------------------ derived
    @property
    def n_obs(self) -> int:
        return len(self.observations)

    @property
    def drive_amplitude(self) -> float | None:
        v = [o.drive_amplitude for o in self.observations if o.drive_amplitude is not None]
        return float(np.mean(v)) if v else None

    @property
    def drive_ratios(self) -> FloatArray:
        """Each observation's drive amplitude over the shared ``B`` (mean ``F_c``), (n_obs,).

        Rows recorded at different free amplitudes (e.g. a set-point series at two drive
        amplitudes, which reaches different indentations) share the law but not the drive:
        observation ``i`` is driven by ``r_i B cos(Omega tau - phi_i)``. All ones when some
        observation has no calibrated drive or the drives agree within ``DRIVE_RATIO_TOL``
        (rows of one free amplitude: their calibrations differ by noise only).
        """
        v = [o.drive_amplitude for o in self.observations]
        if any(a is None for a in v):
            return np.ones(self.n_obs)
        r = np.asarray(v, float) / float(np.mean(np.asarray(v, float)))
        return r if float(np.max(np.abs(r - 1.0))) > DRIVE_RATIO_TOL else np.ones(self.n_obs)

    @property
    def rotated(self) -> NDArray[np.bool_]:
        """Observations whose drive is rotated to a known phase, shape (n_obs,)."""
        return np.isfinite(self.rotations)

    @property
    def n_lin(self) -> int:
        """Lever and drive columns: x', x, [B shared], q_i (rotated) or cos_i, sin_i (free)."""
        r = int(self.rotated.sum())
        return N_LEVER + (1 + r if r else 0) + 2 * (self.n_obs - r)

    @property
    def blocks(self) -> list[tuple[int, int]]:
        """Row ranges of the cross-validation blocks.

        ``fold_by_observation``: one block per observation, in the experiment's order (a
        rolling fold fits some set-points and predicts the next, unseen one); otherwise block
        ``b`` = block ``b`` of every observation.
        """
        if self.fold_by_observation:
            sizes = [o.bound.n_rows for o in self.observations]
        else:
            sizes = [sum(z - a for a, z in (o.bound.blocks[b] for o in self.observations))
                     for b in range(self.n_blocks)]
        edges = np.concatenate([[0], np.cumsum(sizes)])
        return [(int(edges[b]), int(edges[b + 1])) for b in range(len(sizes))]

    def with_drive(self, rotations: Sequence[float], widths: Sequence[float]) -> JointProblem:
        """A copy with the drive columns rotated to ``rotations`` (NaN: free) and priors."""
        r = np.asarray(rotations, float).reshape(self.n_obs)
        w = np.asarray(widths, float).reshape(self.n_obs)
        return dataclasses.replace(self, rotations=r, phase_widths=w)

    def with_offsets(self, offsets: Sequence[float]) -> JointProblem:
        return dataclasses.replace(self, offsets=np.asarray(offsets, float).reshape(self.n_obs))

    def offset_penalty(self) -> float:
        """Prior cost of the offsets in whitened-RSS units."""
        sig = np.array([o.orbit_sigma for o in self.observations])
        return float(self.noise_scale * np.sum((self.offsets / sig) ** 2))

    def with_noise(self, noise_scale: float) -> JointProblem:
        return dataclasses.replace(self, noise_scale=float(max(noise_scale, 1e-300)))

    # ------------------------------------------------------------------ rows
    def _order(self) -> NDArray[np.intp]:
        """Permutation from observation-major to the joint row order (see ``blocks``)."""
        if self.fold_by_observation:
            return np.arange(sum(o.bound.n_rows for o in self.observations))
        offs = np.concatenate([[0], np.cumsum([o.bound.n_rows for o in self.observations])])
        idx = [np.arange(offs[i] + a, offs[i] + z)
               for b in range(self.n_blocks)
               for i, o in enumerate(self.observations)
               for a, z in (o.bound.blocks[b],)]
        return np.concatenate(idx)

    @functools.cached_property
    def _linear(self) -> tuple[FloatArray, FloatArray]:
        return self._linear_columns()

    def linear_columns(self) -> tuple[FloatArray, FloatArray]:
        """Whitened ``y`` (r,) and lever/drive columns (r, n_lin), block-major (cached)."""
        return self._linear

    def _linear_columns(self) -> tuple[FloatArray, FloatArray]:
        n_lin = self.n_lin
        ys, cols = [], []
        rot = self.rotated
        j_free = N_LEVER + (1 + int(rot.sum()) if rot.any() else 0)
        j_q = N_LEVER + 1
        ratios = self.drive_ratios
        for i, o in enumerate(self.observations):
            b = o.bound
            s = 1.0 / o.row_sigma
            lin = np.zeros((b.n_rows, n_lin))
            lin[:, :N_LEVER] = b.linear[:, :N_LEVER] * s
            # a rotated drive's columns carry the observation's drive ratio (shared B)
            rs = s * float(ratios[i]) if rot[i] else s
            c, sn = b.linear[:, 2] * rs, b.linear[:, 3] * rs
            if rot[i]:
                phi = float(self.rotations[i])
                cr, sr = math.cos(phi), math.sin(phi)
                # cos(O t - phi) = cos cr + sin sr ; sin(O t - phi) = sin cr - cos sr
                lin[:, N_LEVER] = c * cr + sn * sr
                lin[:, j_q] = sn * cr - c * sr
                j_q += 1
            else:
                lin[:, j_free], lin[:, j_free + 1] = c, sn
                j_free += 2
            ys.append(b.target * s)
            cols.append(lin)
        order = self._order()
        return np.concatenate(ys)[order], np.concatenate(cols)[order]

    def force_columns(self, library: AFMLibrary, a0: float) -> FloatArray:
        """Whitened ``[theta_j]`` of every observation, shape (r, n_terms), block-major."""
        if not library.n_terms:
            return np.zeros((sum(o.bound.n_rows for o in self.observations), 0))
        f = [o.bound.force_columns(library, a0, gap_shift=float(d)) / o.row_sigma
             for o, d in zip(self.observations, self.offsets, strict=True)]
        return np.concatenate(f)[self._order_cached]

    @functools.cached_property
    def _order_cached(self) -> NDArray[np.intp]:
        return self._order()

    @functools.cached_property
    def block_mean_index(self) -> NDArray[np.intp]:
        """For every joint row, the id of its block-mean row (observation, row within block).

        The force columns of an observation are the same in every block (one denoised orbit),
        so the block means carry all of the force law's information and the orbit's error
        once, not ``n_blocks`` times (see :func:`afmlearn.identify.joint.block_mean_rss`).
        """
        ids = []
        base = 0
        for o in self.observations:  # observation-major: block b's rows -> the same ids
            a0_, z0_ = o.bound.blocks[0]
            ids += [base + np.arange(z - a) for a, z in o.bound.blocks]
            base += z0_ - a0_
        return np.concatenate(ids)[self._order_cached]

    def observation_rows(self, i: int, library: AFMLibrary, a0: float, offset: float
                         ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Observation ``i``'s whitened ``y``, linear and force columns (its own row order)."""
        o = self.observations[i]
        order = self._order_cached
        offs = np.concatenate([[0], np.cumsum([ob.bound.n_rows for ob in self.observations])])
        pos = np.flatnonzero((order >= offs[i]) & (order < offs[i + 1]))
        y, lin = self.linear_columns()
        f = o.bound.force_columns(library, a0, gap_shift=float(offset)) / o.row_sigma
        return y[pos], lin[pos], f[order[pos] - offs[i]]

    def orbit_inputs(self, a0: float, *, offsets: bool = True) -> list[TermInput]:
        """Every observation's denoised orbit as term inputs over its first whole drive
        periods (at least `ORBIT_SAMPLES` samples; the whole record if shorter).

        The orbit is a Fourier series in the drive (periodic), so a term's RMS over whole
        periods is its RMS over the record: the threshold pattern, typical magnitudes and
        start values cost ~4,000 samples per observation instead of 120,000 (600 periods at
        200 samples per period). ``offsets``: add each observation's gap offset.
        """
        out = []
        for o, d in zip(self.observations, self.offsets, strict=True):
            m = _whole_periods(o)
            x, v = o.denoised.x[:m], o.denoised.v[:m]
            out.append(TermInput(z=o.gap + (float(d) if offsets else 0.0) - x, zdot=-v, x=x,
                                 a0=a0))
        return out

    def design(self, library: AFMLibrary, a0: float, *, pattern: bool = True) -> JointDesign:
        """Rows, boxes and threshold pattern (zeros unless ``pattern``) for ``library`` at
        ``a0`` (pure)."""
        y, lin = self.linear_columns()
        theta = np.concatenate([lin, -self.force_columns(library, a0)], axis=1)
        n_lin, p = self.n_lin, theta.shape[1]
        cons = self.constraints
        fc = self.drive_amplitude
        rot = self.rotated
        drive_boxed = bool(rot.any()) and fc is not None
        lo, hi = cons.lever_boxes(p, quality_factor=self.quality_factor,
                                  drive_amplitude=fc if drive_boxed else None,
                                  drive_index=N_LEVER)
        if drive_boxed:
            tb = cons.box("drive")
            for k, i in enumerate(np.flatnonzero(rot)):
                # quadrature B sin(dphi): the drive box, or 3 prior widths of a recorded phase
                w = float(self.phase_widths[i])
                half = fc * min(tb, 3.0 * w) if math.isfinite(w) else fc * tb
                lo[N_LEVER + 1 + k], hi[N_LEVER + 1 + k] = -half, half
        if self.physical_signs and library.n_terms:
            sg = np.array([t.sign for t in library.terms], int)
            lo[n_lin:][sg > 0] = 0.0
            hi[n_lin:][sg < 0] = 0.0
        pat = np.zeros(p)
        if library.n_terms and pattern:
            ev = [library.evaluate(t) for t in self.orbit_inputs(a0)]
            rms = np.sqrt(np.mean(np.concatenate(ev) ** 2, axis=0))
            pat[n_lin:] = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 0.0)
        dead = np.all(theta == 0, axis=0)
        lo[dead], hi[dead] = 0.0, 0.0
        return JointDesign(theta=theta, y=y, lower=lo, upper=hi, pattern=pat,
                           library=library, a0=float(a0))

    def prior(self, p: int) -> tuple[FloatArray, FloatArray]:
        """Calibration and drive-phase priors as Gram additions (shape (p, p), (p,))."""
        s2 = self.noise_scale
        fc = self.drive_amplitude
        rot = self.rotated
        G0, b0 = self.constraints.prior_gram(
            p, quality_factor=self.quality_factor,
            drive_amplitude=fc if rot.any() else None, drive_source=self.drive_source,
            noise_variance=s2, drive_index=N_LEVER)
        if fc is not None:
            # recorded phase: the quadrature B sin(dphi) ~ F_c dphi has a prior of width
            # F_c * width about 0
            for k, i in enumerate(np.flatnonzero(rot)):
                w = float(self.phase_widths[i])
                if math.isfinite(w) and w > 0:
                    G0[N_LEVER + 1 + k, N_LEVER + 1 + k] += s2 / (fc * w) ** 2
        return G0, b0

    # ------------------------------------------------------------------ geometry
    def z_min(self) -> float:
        """Smallest gap reached by any denoised orbit (/ L_ref)."""
        return float(min(np.min(o.gap - o.denoised.x) for o in self.observations))

    def z_span(self) -> float:
        lo = self.z_min()
        hi = float(max(np.max(o.gap - o.denoised.x) for o in self.observations))
        return max(hi - lo, 1e-9)


def observations_of(data: object) -> list[Trace]:
    """The 1-D observations of an ``Experiment``, a ``Trace`` or a sequence of Traces."""
    if isinstance(data, Trace):
        try:
            from afmlearn.io import Experiment  # type: ignore[attr-defined]
        except ImportError:  # pragma: no cover - before the Experiment contract lands
            if data.deflection_m.ndim != 1:
                raise ValueError("a 2-D trace needs afmlearn.io.Experiment to be split into "
                                 "rows") from None
            return [data]
        return list(Experiment.from_trace(data))
    if isinstance(data, Sequence) or hasattr(data, "__iter__"):
        obs = list(data)  # type: ignore[call-overload]
        if not obs or not all(isinstance(o, Trace) for o in obs):
            raise ValueError("data must be an Experiment, a Trace or a non-empty sequence of "
                             f"Traces, got {type(data).__name__}")
        return obs
    raise ValueError(f"data must be an Experiment or a Trace, got {type(data).__name__}")


def _recorded_phase(trace: Trace) -> float | None:
    v = getattr(trace, "drive_phase_rad", None)
    if v is None:
        return None
    v = float(np.asarray(v, float).reshape(-1)[0])
    return -v if math.isfinite(v) else None


def build_problem(traces: Sequence[Trace], *, constraints: CalibrationConstraints,
                  n_blocks: int, max_harmonics: int, min_harmonics: int,
                  projection: HarmonicBalance, physical_signs: bool,
                  a0_range_m: tuple[float, float] | None) -> JointProblem:
    """Check, calibrate, denoise and bind every observation (steady records only).

    Raises
    ------
    ValueError
        A record that cannot be analysed (``check_trace``), a ramp (time-varying gap) among
        several observations, or observations that do not share the calibration.
    """
    if not traces:
        raise ValueError("the experiment has no observation")
    cals = []
    for i, tr in enumerate(traces):
        check_trace(tr)
        if np.ndim(tr.gap_m) != 0:
            raise ValueError(f"observation {i} is a ramp (gap_m varies in time): the joint fit "
                             "takes steady records; identify a ramp on its own")
        cals.append(calibrate(tr))
    q = cals[0].quality_factor
    length = float(np.mean([c.scales.length for c in cals]))
    obs = []
    for tr, cal in zip(traces, cals, strict=True):
        s = cal.scales.length / length
        x = np.asarray(cal.x) * s
        tau = np.asarray(cal.tau)
        spp = cal.samples_per_period
        hf = fit_harmonics(tau, x, cal.omega, max_harmonics=max_harmonics)
        nyq = max(int(spp / 2) - 1, 1)
        n_state = min(max(hf.n_harmonics, min_harmonics), nyq)
        if n_state != hf.n_harmonics:
            hf = fit_harmonics(tau, x, cal.omega, n_harmonics=n_state)
        den = Denoised(x=hf.evaluate(tau), v=hf.evaluate(tau, 1), harmonic_fit=hf)
        rdata = RegressionData(tau=tau, x=x, omega=cal.omega, quality_factor=q, gap=s,
                               samples_per_period=spp, denoised=den)
        bound = projection.bind(rdata, n_blocks=n_blocks)
        sigma_x = float(np.std(x - den.x))
        rms = float(np.std(x)) or 1.0
        row_sigma = max(sigma_x, 1e-7 * rms) * math.sqrt(2.0 * n_blocks / x.size)
        # the orbit at a point: sigma_x sqrt((2 n_h + 1) / n) from the noise, doubled for the
        # truncation of the series at the turning point (measured on DMT series: the
        # denoised minimum gap misses the true one by up to ~2-3 times the noise part)
        orbit_sigma = 2.0 * max(sigma_x, 1e-7 * rms) * math.sqrt(
            (2 * hf.n_harmonics + 1) / x.size)
        fc = None if cal.drive_amplitude is None else cal.drive_amplitude * s
        obs.append(Observation(tau=tau, x=x, gap=s, omega=cal.omega, drive_amplitude=fc,
                               recorded_phase=_recorded_phase(tr), denoised=den, bound=bound,
                               row_sigma=row_sigma, orbit_sigma=orbit_sigma,
                               calibrated=cal))
    zmin = float(min(np.min(o.gap - o.denoised.x) for o in obs))
    span = float(max(np.max(o.gap - o.denoised.x) for o in obs)) - zmin
    lo_a, hi_a = max(zmin, 0.0) + 1e-3 * span, zmin + 0.3 * span
    if a0_range_m is not None:
        lo_a = max(lo_a, a0_range_m[0] / length)
        hi_a = min(hi_a, a0_range_m[1] / length)
        if hi_a <= lo_a:  # the orbits never reach the physical range: keep the orbit scale
            lo_a, hi_a = max(zmin, 0.0) + 1e-3 * span, zmin + 0.3 * span
    n = len(obs)
    return JointProblem(observations=tuple(obs), quality_factor=q,
                        constraints=constraints, drive_source=cals[0].drive_source,
                        rotations=np.full(n, np.nan), phase_widths=np.full(n, np.inf),
                        noise_scale=1.0, physical_signs=physical_signs,
                        a0_range=(float(lo_a), float(hi_a)), n_blocks=n_blocks,
                        length_m=length, offsets=np.zeros(n),
                        fold_by_observation=n >= 3)
