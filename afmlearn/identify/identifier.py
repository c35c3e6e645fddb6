"""`ForceIdentifier`: constrained sparse regression of the tip--sample force from deflection.

Pipeline (physics.md section 5, with the changes the issue's measurements call for):

1. **Calibrate** the trace (``afmlearn.preprocess``): dimensionless time and lengths, ``F_c``.
2. **Split** off the last ``heldout_fraction`` of the periods; it is never used for fitting and
   measures the state accuracy of every candidate.
3. **Denoise** the training span: a Fourier series over all periods when the data are periodic
   (steady state), Savitzky--Golay otherwise. Force terms are evaluated on this state.
4. **Project** the equation of motion on rows (:class:`HarmonicBalance` for periodic data,
   :class:`WeakForm` otherwise): no derivative of noisy data is ever taken.
5. **Constrain** ``K``, ``D``, ``B`` by boxes and calibration priors
   (:class:`CalibrationConstraints`); the drive phase is estimated, then the drive is rotated so
   that its amplitude gets a box.
6. **Contact onset a0** is profiled jointly: every ``a0`` on a grid spanning the orbit's
   smallest gaps gets its own sparse fit; the best (and a bounded refinement) is kept.
7. **Model selection**: threshold x nu grid (:class:`GridSearch`, rolling cross-validation),
   each distinct support scored by held-out state error (simulation from the measured state)
   and, when the true force is given (training), force error; the knee of the 3-D Pareto front
   is the choice, AICc the second opinion.
8. **Refine** the continuous parameters of the chosen support (``a0``, exponents, decay
   lengths) by Nelder--Mead on the constrained least-squares residual.
9. **Bag** the chosen model with a moving-block bootstrap over row blocks, constraints kept, for
   coefficient and force bands.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any, final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize, minimize_scalar
from sklearn.base import clone

from afmlearn.io import Experiment, Trace
from afmlearn.metrics import nrmse
from afmlearn.preprocess import (
    Calibrated,
    HarmonicFit,
    calibrate,
    check_trace,
    default_window,
    fit_harmonics,
    savgol_derivatives,
)

from .constraints import CalibrationConstraints
from .drive import AbstractDrivePhase
from .joint import (
    Bagging,
    ContactOnsetProfile,
    ExponentProfile,
    OrbitOffsets,
    Refinement,
    SupportSelection,
)
from .library import (
    AFMLibrary,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
    SphereElectrostatic,
    TermInput,
)
from .library._kernel import force_series
from .model import IdentifiedModel
from .optimizers import BoxSR3
from .projection import AbstractProjection, Denoised, HarmonicBalance, RegressionData
from .selection import Candidate, GridSearch, best_by_ic
from .selection import knee_one_se as _knee_on_front
from .selection import merge_supports as _merge
from .selection import profile_interval as _profile_interval
from .stepwise import ForwardSelection, cv_errors
from .summary import force_vs_gap, summarize
from .weak import WeakForm

__all__ = ["ForceIdentifier", "LINEAR_TERMS", "force_vs_gap", "summarize"]

FloatArray = NDArray[np.float64]

#: names of the four lever/drive columns that precede the force terms
LINEAR_TERMS = ("x'", "x", "cos(Omega tau)", "sin(Omega tau)")
_N_LIN = 4


@final
@dataclass
class _Design:
    """Rows of one (library, a0, drive rotation): Theta (r, p), y (r,)."""

    theta: FloatArray
    y: FloatArray
    library: AFMLibrary
    a0: float


@final
class ForceIdentifier:
    """Identify ``F_ts`` and the equation of motion from one deflection trace.

    scikit-learn style: ``__init__`` stores settings, :meth:`fit` sets attributes ending in
    ``_``. All options are keyword-only.

    Parameters
    ----------
    library : AFMLibrary, optional
        Candidate force terms; default :meth:`AFMLibrary.standard`.
    projection : AbstractProjection, optional
        :class:`HarmonicBalance` or :class:`WeakForm`; None picks HarmonicBalance for periodic
        data and WeakForm otherwise.
    constraints : CalibrationConstraints
        Boxes and priors on ``K``, ``D``, ``B``.
    thresholds : array-like, optional
        Threshold grid (force units ``k L_ref`` of a term's RMS contribution); default
        ``geomspace(0.01, 10, 10) / Q`` times the orbit's RMS deflection.
    nus : array-like, optional
        SR3 relaxation grid; default ``default_nu_grid(5)`` (unit-normalised columns).
    n_folds : int
        Rolling cross-validation folds (>= 2).
    heldout_fraction : float
        Share of the periods (at the end) kept out of every fit, in [0.1, 0.5].
    n_a0 : int
        ``a0`` profile grid points (>= 4).
    refine : bool
        Refine ``a0``, exponents and decay lengths of the chosen model.
    n_bootstrap : int
        Bagged models for the uncertainty bands (0: no bands).
    max_harmonics : int
        Largest Fourier order of the periodic denoiser's noise-floor search.
    min_harmonics : int
        Smallest Fourier order of the denoised state (periodic data).
    max_terms : int
        Largest number of force terms of the forward-selected supports.
    substeps : int or None
        RK4 steps per sample in the state-accuracy simulations (None: at least 400 steps per
        drive period).
    max_heldout_periods : float
        Longest simulated held-out span (the rest of the held-out data is not simulated).
    physical_signs : bool
        Bound the force coefficients of physically signed terms (``AbstractTerm.sign``):
        elastic contact repulsive, damping dissipative, electrostatics attractive.
    a0_range_m : (float, float) or None
        Physical range of the contact onset ``a0`` in metres (an intermolecular distance;
        default 0.1 to 3 nm), converted with the trace's rest gap; None: only the orbit's
        own scale bounds ``a0`` (0.1 % to 30 % of the gap span).
    drive_phase : AbstractDrivePhase, optional
        How each observation's drive phase enters a joint fit: :class:`RecordedPhase`
        (default: the file's ``drive_phase_rad`` with a 0.01 rad prior where recorded, fitted
        elsewhere) or :class:`FittedPhase` (always fitted).
    exponent_profile : ExponentProfile, optional
        Range and steps of the contact exponent's profile likelihood in a joint fit.
    seed : int
        Seed of the bootstrap.
    progress : bool
        Print the stages to stderr.

    Attributes
    ----------
    calibrated_ : Calibrated
    model_ : IdentifiedModel
        The chosen model (knee of the Pareto front), refined.
    ic_model_ : IdentifiedModel
        The AICc choice (second opinion; not refined).
    candidates_ : list of Candidate
        Distinct supports with ``scores`` "state_error" (and "force_error").
    knee_index_, ic_index_ : int
    a0_profile_ : ndarray, shape (n_a0, 2)
        ``(a0, objective)`` of the profile.
    force_, force_lo_, force_hi_ : ndarray, shape (n,)
        Identified ``F_ts`` [k L_ref] on every sample and its 95 % band (NaN where undefined).
    state_x_, state_v_ : ndarray, shape (n,)
        Denoised deflection and rate used to evaluate the force.
    heldout_start_ : int
        First held-out sample.
    periodic_ : bool
    summary_ : dict
        Interaction exponent with its 95 % profile-likelihood interval, dissipated energy per
        cycle, peak repulsive force, contact time, state accuracy (dimensionless and SI).
    exponent_profile_ : ndarray, shape (n_p, 2) or None
        ``(p, RSS)``: the residual of the chosen support with its dominant ``delta^p`` set to
        ``p`` (``a0`` and coefficients re-fitted); None without a contact term.
    warnings_ : list of str
    """

    def __init__(self, *, library: AFMLibrary | None = None,
                 projection: AbstractProjection | None = None,
                 constraints: CalibrationConstraints | None = None,
                 thresholds: Any = None, nus: Any = None, n_folds: int = 10,
                 heldout_fraction: float = 0.3, n_a0: int = 12, refine: bool = True,
                 n_bootstrap: int = 40, max_harmonics: int = 100, min_harmonics: int = 30,
                 max_terms: int = 6, max_heldout_periods: float = 60.0,
                 substeps: int | None = None, physical_signs: bool = True,
                 a0_range_m: tuple[float, float] | None = (0.1e-9, 3.0e-9),
                 drive_phase: AbstractDrivePhase | None = None,
                 exponent_profile: ExponentProfile | None = None,
                 seed: int = 0, progress: bool = False) -> None:
        self.library = library
        self.projection = projection
        self.constraints = constraints
        self.thresholds = thresholds
        self.nus = nus
        self.n_folds = n_folds
        self.heldout_fraction = heldout_fraction
        self.n_a0 = n_a0
        self.refine = refine
        self.n_bootstrap = n_bootstrap
        self.max_harmonics = max_harmonics
        self.min_harmonics = min_harmonics
        self.max_terms = max_terms
        self.max_heldout_periods = max_heldout_periods
        self.substeps = substeps
        self.physical_signs = physical_signs
        self.a0_range_m = a0_range_m
        self.drive_phase = drive_phase
        self.exponent_profile = exponent_profile
        self.seed = seed
        self.progress = progress

    # ------------------------------------------------------------------ settings
    def _check(self) -> None:
        if self.library is not None and not isinstance(self.library, AFMLibrary):
            raise ValueError(f"library must be an AFMLibrary, got {self.library!r}")
        if self.projection is not None and not isinstance(self.projection, AbstractProjection):
            raise ValueError(f"projection must be HarmonicBalance or WeakForm, "
                             f"got {self.projection!r}")
        if self.drive_phase is not None and not isinstance(self.drive_phase,
                                                           AbstractDrivePhase):
            raise ValueError(f"drive_phase must be RecordedPhase or FittedPhase, "
                             f"got {self.drive_phase!r}")
        if self.exponent_profile is not None and not isinstance(self.exponent_profile,
                                                                ExponentProfile):
            raise ValueError(f"exponent_profile must be an ExponentProfile, "
                             f"got {self.exponent_profile!r}")
        if not (isinstance(self.n_folds, int) and self.n_folds >= 2):
            raise ValueError(f"n_folds must be an integer >= 2, got {self.n_folds!r}")
        if self.a0_range_m is not None:
            r = tuple(self.a0_range_m)
            if not (len(r) == 2 and 0 < r[0] < r[1] and all(map(math.isfinite, r))):
                raise ValueError(f"a0_range_m must be (low, high) metres with 0 < low < high, "
                                 f"got {self.a0_range_m!r}")
        if not 0.1 <= self.heldout_fraction <= 0.5:
            raise ValueError(f"heldout_fraction must be in [0.1, 0.5], "
                             f"got {self.heldout_fraction!r}")
        if not (isinstance(self.n_a0, int) and self.n_a0 >= 4):
            raise ValueError(f"n_a0 must be an integer >= 4, got {self.n_a0!r}")
        if not (isinstance(self.n_bootstrap, int) and self.n_bootstrap >= 0):
            raise ValueError(f"n_bootstrap must be an integer >= 0, got {self.n_bootstrap!r}")
        if self.substeps is not None and not (isinstance(self.substeps, int)
                                              and self.substeps >= 1):
            raise ValueError(f"substeps must be an integer >= 1 or None, got {self.substeps!r}")

    def _log(self, msg: str) -> None:
        if self.progress:
            import sys
            import time
            print(f"[identify {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)

    # ------------------------------------------------------------------ joint fit
    def fit_joint(self, data: Experiment | Trace) -> ForceIdentifier:
        """The joint pipeline on any experiment, also one of a single steady observation.

        :meth:`fit` uses it for experiments of several observations; this entry point lets a
        single orbit be fitted the same way (side-by-side benchmarks on the same method).
        """
        self._check()
        obs = list(data) if isinstance(data, Experiment) else [data]
        if len(obs) == 1 and obs[0].deflection_m is not None \
                and obs[0].deflection_m.ndim == 2:
            obs = list(Experiment.from_trace(obs[0]))
        return self._fit_joint(obs)

    def _fit_joint(self, traces: list[Trace]) -> ForceIdentifier:
        """Joint fit of several steady observations: problem, stages, outputs (no state)."""
        from .joint import fit_joint
        from .joint_outputs import joint_force, joint_model, joint_summary
        from .problem import build_problem

        self.warnings_ = []
        library = AFMLibrary.standard() if self.library is None else self.library
        if self.projection is not None and not isinstance(self.projection, HarmonicBalance):
            raise ValueError("a joint fit of steady observations uses HarmonicBalance; got "
                             f"{type(self.projection).__name__}")
        self._log(f"joint fit of {len(traces)} observations")
        problem = build_problem(
            traces, constraints=self.constraints or CalibrationConstraints(),
            n_blocks=self.n_folds + 1, max_harmonics=self.max_harmonics,
            min_harmonics=self.min_harmonics, projection=self.projection or HarmonicBalance(),
            physical_signs=self.physical_signs,
            a0_range_m=None if self.a0_range_m is None else tuple(self.a0_range_m))
        if problem.drive_amplitude is None:
            self.warnings_.append("no free data (free_deflection_m or free_amplitude_m): the "
                                  "drive amplitude is not constrained")
        res = fit_joint(problem, library, drive=self.drive_phase,
                        onset=ContactOnsetProfile(n_a0=self.n_a0),
                        selection=SupportSelection(max_terms=self.max_terms),
                        refinement=Refinement() if self.refine else None,
                        bagging=Bagging(n_bootstrap=self.n_bootstrap, seed=self.seed),
                        exponent=self.exponent_profile or ExponentProfile(),
                        offsets=OrbitOffsets(), log=self._log)
        n_lin = res.problem.n_lin
        bands = (None if res.samples.shape[0] < 5
                 else np.percentile(res.samples[:, n_lin:], [2.5, 97.5], axis=0))
        chosen = res.candidates[res.knee_index]
        self.model_ = joint_model(res, res.coef, res.library, res.a0, bands=bands, info={
            "n_terms": chosen.n_terms, "cv_error": chosen.cv_error,
            "projection": "HarmonicBalance", "periodic": True, "joint": True,
            "n_observations": res.problem.n_obs})
        self.ic_model_ = joint_model(res, res.ic_coef, res.selection_library,
                                     res.selection_a0)
        forces = joint_force(res)
        self.joint_ = res
        self.candidates_ = res.candidates
        self.knee_index_, self.ic_index_ = res.knee_index, res.ic_index
        self.objectives_ = ("cv_error",)
        self.search_ = None
        self.a0_profile_ = res.a0_profile
        self.refined_ = res.refined
        self.periodic_ = True
        self.projection_ = self.projection or HarmonicBalance()
        self.force_, self.force_lo_, self.force_hi_ = forces["force"], forces["lo"], forces["hi"]
        self.state_x_, self.state_v_ = forces["x"], forces["v"]
        self.heldout_start_ = int(forces["x"].shape[1])  # nothing held out: CV over blocks
        self.exponent_profile_ = None if res.exponent is None else res.exponent["profile"]
        self.summary_ = joint_summary(res, self.model_, forces)
        self.drive_phase_candidates_ = []
        return self

    # ------------------------------------------------------------------ fit
    def fit(self, data: Experiment | Trace | Calibrated, *, row: int | None = None,
            true_force: FloatArray | None = None) -> ForceIdentifier:
        """Identify ONE force law from an experiment (all its observations jointly).

        Parameters
        ----------
        data : Experiment, Trace or Calibrated
            An ``afmlearn.io.Experiment`` with several steady observations (a set-point
            series) is fitted jointly (:mod:`afmlearn.identify.joint`): shared ``a0``,
            exponents and coefficients, a drive phase per observation. A Trace is wrapped as
            an experiment (a series file's rows are its observations); an experiment of one
            observation (a single trace, a ramp, one row) is fitted by the single-orbit
            pipeline. Labels are never read.
        row : int, optional
            Row of a sweep or series: identify that row alone.
        true_force : ndarray, shape (n,), optional
            The true ``F_ts`` [k L_ref] (single-orbit training on simulations only): adds the
            force error to the Pareto front.

        Returns
        -------
        self
        """
        self._check()
        obs = None
        if isinstance(data, Experiment):
            obs = list(data)
        elif isinstance(data, Trace) and data.deflection_m.ndim == 2 and row is None \
                and data.is_series:
            obs = list(Experiment.from_trace(data))
        if obs is not None and len(obs) > 1:
            if true_force is not None:
                raise ValueError("true_force is for single-orbit training; a joint fit takes "
                                 "none")
            return self._fit_joint(obs)
        if obs is not None:
            data = obs[0]
        if isinstance(data, Trace):
            check_trace(data, row=row)
            cal = calibrate(data, row=row)
        elif isinstance(data, Calibrated):
            cal = data
        else:
            raise ValueError(f"data must be a Trace or Calibrated, got {type(data).__name__}")
        self.warnings_: list[str] = []
        if cal.excitation_assumed:
            self.warnings_.append("excitation not recorded in the file: tip excitation assumed")
        if cal.drive_amplitude is None:
            self.warnings_.append("no free data (free_deflection_m or free_amplitude_m): the "
                                  "drive amplitude is not constrained")
        if cal.excitation == "base":
            self.warnings_.append("base excitation: the dither's own contribution to the gap "
                                  "is neglected (it is below 1 % of the gap for typical dithers)")
        cons = self.constraints or CalibrationConstraints()
        library = AFMLibrary.standard() if self.library is None else self.library
        n = cal.n_samples
        spp = cal.samples_per_period
        if true_force is not None:
            true_force = np.asarray(true_force, float)
            if true_force.shape != (n,):
                raise ValueError(f"true_force must have shape ({n},), got {true_force.shape}")
        # -- 2. split
        n_periods = n / spp
        fit_periods = math.floor(n_periods * (1 - self.heldout_fraction))
        if fit_periods < self.n_folds + 1:
            raise ValueError(
                f"trace too short: {n_periods:.1f} periods leave {fit_periods} for fitting, "
                f"need >= n_folds + 1 = {self.n_folds + 1}")
        n_fit = int(round(fit_periods * spp))
        self.heldout_start_ = n_fit
        tau, x = cal.tau, cal.x
        gap = cal.gap
        gap_fit = gap if np.isscalar(gap) else np.asarray(gap)[:n_fit]
        # -- 3. denoise
        self._log("denoising")
        periodic = False
        hf: HarmonicFit | None = None
        if np.isscalar(gap) and not isinstance(self.projection, WeakForm):
            hf = fit_harmonics(tau[:n_fit], x[:n_fit], cal.omega,
                               max_harmonics=self.max_harmonics)
            # the noise-floor order keeps only harmonics above a 1 % family-wise false alarm;
            # the contact's shape lives in weaker ones, so the state keeps at least
            # `min_harmonics` (noise cost: sigma * sqrt((2 n_h + 1) / n_samples))
            nyq = max(int(spp / 2) - 1, 1)
            n_state = min(max(hf.n_harmonics, self.min_harmonics), nyq)
            if n_state != hf.n_harmonics:
                hf = fit_harmonics(tau[:n_fit], x[:n_fit], cal.omega, n_harmonics=n_state)
            periodic = bool(hf.is_periodic) or isinstance(self.projection, HarmonicBalance)
        if periodic:
            assert hf is not None
            den = Denoised(x=hf.evaluate(tau[:n_fit]), v=hf.evaluate(tau[:n_fit], 1),
                           harmonic_fit=hf)
            proj = self.projection or HarmonicBalance()
        else:
            win = default_window(spp)
            xs, xd, _ = savgol_derivatives(x[:n_fit], float(tau[1] - tau[0]), window=win)
            den = Denoised(x=xs, v=xd)
            proj = self.projection if isinstance(self.projection, WeakForm) else WeakForm()
        self.periodic_ = periodic
        self.projection_ = proj
        rdata = RegressionData(tau=tau[:n_fit], x=x[:n_fit], omega=cal.omega,
                               quality_factor=cal.quality_factor,
                               gap=gap_fit if np.isscalar(gap_fit) else np.asarray(gap_fit),
                               samples_per_period=spp, denoised=den)
        bound = proj.bind(rdata, n_blocks=self.n_folds + 1)
        self._bound = bound
        self._cal = cal
        self._cons = cons
        self._ref_cache = None
        self._den = den
        self._tau_fit = tau[:n_fit]
        self.drive_phase_candidates_: list[tuple[float, float]] = []
        # -- constraints: boxes, priors, threshold pattern
        z_orbit = np.asarray(gap_fit) - den.x
        rms_x = float(np.sqrt(np.mean((den.x - den.x.mean()) ** 2))) or 1.0
        self._rms_x = rms_x
        q = cal.quality_factor
        fc = cal.drive_amplitude
        ts = (np.geomspace(0.01, 10.0, 10) / q * rms_x if self.thresholds is None
              else np.atleast_1d(np.asarray(self.thresholds, float)))
        nus = (np.geomspace(1.0, 1e4, 5) if self.nus is None
               else np.atleast_1d(np.asarray(self.nus, float)))
        self._ts, self._nus = ts, nus
        # -- 5/6. drive phase and a0 profile
        self._log("a0 profile")
        self._rotation = 0.0
        self._drive_rotated = False
        zmin, zmax = float(np.min(z_orbit)), float(np.max(z_orbit))
        span = max(zmax - zmin, 1e-9)
        # candidates: contact depths a0 - zmin and absolute a0 (both geometric, 0.1 % to 30 %
        # of the orbit's gap span; a0 > 0 since long-range terms are held at a0 in contact),
        # plus "no contact" (a0 below the orbit) when the orbit stays at positive gaps
        g = np.geomspace(1e-3 * span, 0.3 * span, self.n_a0)
        a0_grid = np.unique(np.concatenate([zmin + g, g]))
        a0_grid = a0_grid[(a0_grid > max(zmin, 0.0)) & (a0_grid <= zmin + 0.3 * span)]
        if self.a0_range_m is not None:
            # a0 is an intermolecular distance: keep the physical range (SI / L_ref), where
            # the profile is nearly flat along (a0, exponent, stiffness) and would otherwise
            # drift to sub-atomic onsets with steep exponents
            lo_a, hi_a = (v / cal.scales.length for v in self.a0_range_m)
            phys = np.geomspace(max(lo_a, zmin + 1e-3 * span), hi_a, self.n_a0) if (
                hi_a > max(lo_a, zmin + 1e-3 * span)) else np.empty(0)
            a0_grid = np.unique(np.concatenate([a0_grid, phys]))
            a0_grid = a0_grid[(a0_grid >= lo_a) & (a0_grid <= hi_a) & (a0_grid > zmin)]
        if zmin - 0.01 * span > 0:
            a0_grid = np.concatenate([[zmin - 0.01 * span], a0_grid])
        if a0_grid.size == 0:  # the orbit never reaches the physical contact range
            a0_grid = np.array([zmin - 0.01 * span])
        self._a0_range = (float(a0_grid.min()), float(a0_grid.max()))
        self._sigma2 = None
        prof = []
        for a0 in a0_grid:
            prof.append((a0, self._profile_objective(library, float(a0))))
        prof_arr = np.array(prof)
        i = int(np.nanargmin(prof_arr[:, 1]))
        a0_best = float(prof_arr[i, 0])
        if 0 < i < len(a0_grid) - 1:
            lo, hi = float(a0_grid[i - 1]), float(a0_grid[i + 1])
            res = minimize_scalar(lambda a: self._profile_objective(library, a),
                                  bounds=(lo, hi), method="bounded",
                                  options={"xatol": 1e-4 * span, "maxiter": 10})
            if res.fun < prof_arr[i, 1]:
                a0_best = float(res.x)
        self.a0_profile_ = prof_arr
        # drive phase from an unrotated fit at a0_best, then rotate and box the amplitude
        self._rotation = self._drive_phase(library, a0_best)
        self._drive_rotated = fc is not None
        self._sigma2 = None
        # -- 7. model selection, alternating with a0: select a support at the profiled a0,
        # re-profile a0 for that support (the profile's short models may prefer another
        # contact onset), select again there
        self._log("model selection")
        des, search, cands = self._select(library, a0_best)
        first = cands[_knee_on_front(cands, ("cv_error",))]
        keep = first.coef[0][_N_LIN:] != 0
        a0_new, aic_gain = a0_best, 0.0
        if keep.any():
            lib_first = des.library.subset(keep)
            a0_new = self._profile_fixed(lib_first, a0_best)
            # a0 is one more fitted parameter: move only on an AIC gain (n log(RSS1/RSS0) < -2)
            r0 = self._support_rss(lib_first, a0_best)
            r1 = self._support_rss(lib_first, a0_new)
            aic_gain = des.y.size * math.log(max(r1, 1e-300) / max(r0, 1e-300))
        if abs(a0_new - a0_best) > 1e-3 * span and aic_gain < -2.0:
            self._log(f"a0 {a0_best:.4g} -> {a0_new:.4g} for the chosen support; reselecting")
            des, search, cands = self._select(library, a0_new)
        self._log(f"scoring {len(cands)} candidate supports")
        for c in cands:
            m = self._to_model(des.library, des.a0, c.coef[0])
            c.scores["state_error"] = self._state_error(m)
            if true_force is not None:
                c.scores["force_error"] = self._force_error(m, true_force[:n_fit])
        # rolling-CV error of the projected equation is the sharpest out-of-sample signal;
        # the held-out simulated orbit and (training only) the force complete the front
        objectives = (("cv_error", "state_error", "force_error") if true_force is not None
                      else ("cv_error", "state_error"))
        ki = _knee_on_front(cands, objectives)
        ii = best_by_ic(cands, "aicc")
        self.search_ = search
        self.candidates_ = cands
        self.objectives_ = objectives
        self.knee_index_, self.ic_index_ = ki, ii
        chosen = cands[ki]
        self.ic_model_ = self._to_model(des.library, des.a0, cands[ii].coef[0])
        # -- 8. refine continuous parameters on the chosen support
        support = chosen.coef[0] != 0
        lib_s = des.library.subset(support[_N_LIN:])
        a0_final = des.a0
        self.refined_ = False
        if self.refine and lib_s.n_terms:
            self._log("refining a0 and exponents")
            lib_r, a0_r = self._refine(lib_s, a0_final)
            # accept only an out-of-sample gain (paired over the CV folds): along the flat
            # valleys of (a0, exponent, stiffness) the residual alone wanders to the bounds
            e0 = self._cv(lib_s, a0_final)
            e1 = self._cv(lib_r, a0_r)
            d = e1 - e0
            if (np.all(np.isfinite(d)) and d.size > 1
                    and float(d.mean()) < -float(d.std(ddof=1)) / np.sqrt(d.size)):
                lib_s, a0_final, self.refined_ = lib_r, a0_r, True
        des_f = self._design(lib_s, a0_final)
        supp_f = np.ones(des_f.theta.shape[1], bool)
        coef_f = self._refit(des_f, supp_f)
        # -- 9. bagging
        self._lib_final = lib_s
        samples = self._bag(des_f, supp_f) if self.n_bootstrap else None
        bands = (None if samples is None
                 else np.percentile(samples[:, _N_LIN:], [2.5, 97.5], axis=0))
        model = self._to_model(lib_s, a0_final, coef_f, bands=bands, info={
            "threshold": chosen.threshold, "nu": chosen.nu, "n_terms": chosen.n_terms,
            "cv_error": chosen.cv_error, "scores": dict(chosen.scores),
            "projection": type(proj).__name__, "periodic": periodic,
        })
        self.model_ = model
        self._bag_samples = samples
        # -- outputs on the whole trace
        self._outputs(model, samples, true_force)
        return self

    # ------------------------------------------------------------------ pieces
    def _template(self, threshold: float | None = None, nu: float = 1.0) -> BoxSR3:
        """A fresh BoxSR3 with this problem's boxes and per-term thresholds.

        ``threshold`` (force units) is the smallest RMS contribution a term may have; the
        per-coefficient thresholds are ``threshold * pattern`` (see :meth:`_design`).
        """
        t = float(self._ts[0] if threshold is None else threshold)
        t = max(t, 1e-300)
        return clone(self._tmpl).set_params(threshold=t, thresholds=t * self._pattern, nu=nu)

    def _design(self, library: AFMLibrary, a0: float) -> _Design:
        """Rows for ``library`` at ``a0``; also sets the optimizer template for its columns."""
        b = self._bound
        lin = b.linear.copy()
        if self._rotation:
            c, s = lin[:, 2].copy(), lin[:, 3].copy()
            cr, sr = math.cos(self._rotation), math.sin(self._rotation)
            # cos(Ot - r) = cos cr + sin sr ; sin(Ot - r) = sin cr - cos sr
            lin[:, 2] = c * cr + s * sr
            lin[:, 3] = s * cr - c * sr
        fcol = b.force_columns(library, a0) if library.n_terms else np.empty((b.n_rows, 0))
        theta = np.concatenate([lin, -fcol], axis=1)
        p = theta.shape[1]
        cal, cons = self._cal, self._cons
        fc = cal.drive_amplitude
        # unrotated (first pass): the drive is free, so the data set its phase
        rotated = fc is not None and self._drive_rotated
        lo, hi = cons.lever_boxes(p, quality_factor=cal.quality_factor,
                                  drive_amplitude=fc if rotated else None)
        if rotated:
            tb = cons.box("drive")
            lo[3], hi[3] = -fc * tb, fc * tb
        if self.physical_signs:
            sg = np.array([t.sign for t in library.terms], int)
            lo[_N_LIN:][sg > 0] = 0.0
            hi[_N_LIN:][sg < 0] = 0.0
        # thresholds act on a term's RMS contribution: pattern_j = 1 / rms(theta_j) on the orbit
        pattern = np.zeros(p)
        if library.n_terms:
            d = self._den
            gap = self._bound_gap()
            s = TermInput(z=gap - d.x, zdot=-d.v, x=d.x, a0=a0)
            rms = np.sqrt(np.mean(library.evaluate(s) ** 2, axis=0))
            pattern[_N_LIN:] = np.where(rms > 0, 1.0 / np.where(rms > 0, rms, 1.0), 0.0)
        # columns that vanish (e.g. contact terms without contact) are pinned to zero
        dead = np.all(theta == 0, axis=0)
        lo[dead], hi[dead] = 0.0, 0.0
        self._pattern = pattern
        self._tmpl = BoxSR3(threshold=1.0, nu=1.0, thresholds=pattern, lower=lo, upper=hi,
                            normalize_columns=True, max_iter=250, tol=1e-9, unbias=True)
        return _Design(theta=theta, y=b.target, library=library, a0=a0)

    def _bound_gap(self) -> FloatArray | float:
        g = self._cal.gap
        return g if np.isscalar(g) else np.asarray(g)[: self.heldout_start_]

    def _gram(self, des: _Design) -> tuple[FloatArray, FloatArray]:
        G0, b0 = self._prior_gram(des)
        return des.theta.T @ des.theta + G0, des.theta.T @ des.y + b0

    def _prior_gram(self, des: _Design) -> tuple[FloatArray, FloatArray]:
        """Calibration priors as Gram additions ``sum_k w_k^2 (xi_k - mu_k)^2``."""
        p = des.theta.shape[1]
        if self._sigma2 is None:
            # row noise from a dense box-constrained fit (no threshold, no prior)
            tmpl = self._template()
            G = des.theta.T @ des.theta
            c = tmpl.refit_gram(G, des.theta.T @ des.y, np.ones(p, bool))[0]
            r = des.y - des.theta @ c
            dof = max(des.theta.shape[0] - p, 1)
            self._sigma2 = float(r @ r / dof) or 1e-30
        cal = self._cal
        return self._cons.prior_gram(
            p, quality_factor=cal.quality_factor,
            drive_amplitude=cal.drive_amplitude if self._drive_rotated else None,
            drive_source=cal.drive_source, noise_variance=self._sigma2)

    def _with_prior_rows(self, des: _Design) -> tuple[FloatArray, FloatArray]:
        """Rows with the prior as pseudo-rows, spread evenly over the CV blocks.

        Each of the ``nb`` blocks carries ``1/nb`` of the prior, so a rolling fold trained on
        ``f`` blocks sees ``f/nb`` of it (prior-to-data ratio fixed) and the fit on all rows sees
        exactly the prior of :meth:`_prior_gram`.
        """
        G0, b0 = self._prior_gram(des)
        idx = np.flatnonzero(np.diag(G0) > 0)
        blocks = self._bound.blocks
        nb = len(blocks)
        p = des.theta.shape[1]
        pr = np.zeros((idx.size, p))
        w = np.sqrt(np.diag(G0)[idx] / nb)
        pr[np.arange(idx.size), idx] = w
        py = b0[idx] / np.diag(G0)[idx] * w
        th, yy = [], []
        for a, z in blocks:
            th += [des.theta[a:z], pr]
            yy += [des.y[a:z], py]
        return np.concatenate(th), np.concatenate(yy)

    def _select(self, library: AFMLibrary, a0: float
                ) -> tuple[_Design, GridSearch, list[Candidate]]:
        """SR3 threshold x nu grid plus forward selection at ``a0``; distinct supports."""
        des = self._design(library, a0)
        theta_p, y_p = self._with_prior_rows(des)
        search = GridSearch(self._template(), self._ts, self._nus, n_folds=self.n_folds)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            search.fit(theta_p, y_p)
        fwd = ForwardSelection(self._template(), always=range(_N_LIN),
                               max_terms=self.max_terms).fit(des.theta, des.y,
                                                             self._bound.blocks,
                                                             prior=self._prior_gram(des))
        return des, search, _merge(search.candidates_, fwd.candidates_)

    def _profile_fixed(self, lib: AFMLibrary, a0: float, n: int = 40) -> float:
        """Least-squares profile of ``a0`` for a fixed support (grid plus bounded refinement)."""
        if not any(t.contact_only for t in lib.terms) and not any(
                isinstance(t, InversePower | SphereElectrostatic) for t in lib.terms):
            return a0
        lo, hi = self._a0_range

        def rss(a: float) -> float:
            return self._support_rss(lib, a)

        grid = np.unique(np.concatenate([np.geomspace(lo, hi, n), [a0]]))
        vals = np.array([rss(a) for a in grid])
        i = int(np.argmin(vals))
        if 0 < i < grid.size - 1:
            res = minimize_scalar(rss, bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                                  options={"xatol": 1e-4 * (hi - lo), "maxiter": 15})
            if res.fun < vals[i]:
                return float(res.x)
        return float(grid[i])

    def _drive_phase(self, library: AFMLibrary, a0: float) -> float:
        """Drive phase: the best of a few candidate phases with the drive amplitude boxed.

        The fundamental's balance is ``(K - Omega^2 + i Omega D) X_1 + F_1 = B e^{-i phi}``.
        With a free drive (amplitude and phase) these two equations are absorbed by the drive,
        so a free fit sets ``phi`` only through the force's other harmonics; when those are
        below the noise (small, nearly linear orbits) ``phi`` is undetermined and the free
        fit can land on the mirror branch (force gradient of the wrong sign, the drive phase
        flipped by ~pi). The calibrated amplitude ``|B| = F_c`` removes that freedom: a
        conservative ``F_1 = s X_1`` must satisfy ``|K + s - Omega^2 + i Omega D| =
        F_c / |X_1|``, two roots ``s``. The candidates are the free fit's phase and the two
        roots' phases; for each, the best short model is selected with the drive rotated to
        it and boxed (amplitude and quadrature within the drive tolerance), and the lowest
        AIC wins. The phase is not refined further by least squares: a drive quadrature
        error trades against dissipative terms (the fundamental's quadrature balance), so a
        free phase would buy fake dissipation; the box leaves +-tolerance of quadrature.
        Without a calibrated drive the free fit's phase is returned.
        """
        best, _ = self._short_models(library, a0)
        c = best.coef[0]
        phi_free = float(math.atan2(c[3], c[2]))
        fc = self._cal.drive_amplitude
        if fc is None:
            return phi_free
        cands = [phi_free, *self._conservative_phases(fc)]
        distinct: list[float] = []
        for phi in cands:
            if all(abs(math.remainder(phi - d, 2 * math.pi)) > 0.02 for d in distinct):
                distinct.append(phi)
        scored = []
        try:
            for phi in distinct:
                self._rotation, self._drive_rotated = phi, True
                cand, aic = self._short_models(library, a0)
                scored.append((aic, phi, cand))
            # the conservative roots are exact for conservative forces; within 2 AIC units
            # (no evidence either way) prefer them: a free phase buys fake dissipation
            best_aic = min(a for a, _, _ in scored)
            roots = [t for t in scored[1:] if t[0] <= best_aic + 2.0] if len(distinct) > 1 \
                and distinct[0] == phi_free else []
            aic, phi, cand = min(roots or scored, key=lambda t: t[0])
        finally:
            self._rotation, self._drive_rotated = 0.0, False
        self.drive_phase_candidates_ = [(float(p), float(a)) for a, p, _ in scored]
        return float(phi)

    def _conservative_phases(self, fc: float) -> list[float]:
        """Drive phases of the two conservative roots of the fundamental's balance."""
        om = self._cal.omega
        x1 = complex(fit_harmonics(self._tau_fit, self._den.x, om,
                                   n_harmonics=1).complex_amplitudes[1])
        if abs(x1) == 0:
            return []
        dd = om / self._cal.quality_factor
        rad = math.sqrt(max((fc / abs(x1)) ** 2 - dd**2, 0.0))
        out = []
        for re in (rad, -rad):  # re = K + s - Omega^2
            e = complex(re, dd) * x1 / fc  # = e^{-i phi}
            out.append(float(-math.atan2(e.imag, e.real)))
        return out

    def _short_models(self, library: AFMLibrary, a0: float) -> tuple[Candidate, float]:
        """Best (by AIC) of the forward-selected supports with up to three force terms."""
        des = self._design(library, a0)
        fwd = ForwardSelection(self._template(), always=range(_N_LIN), max_terms=3,
                               cross_validate=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fwd.fit(des.theta, des.y, self._bound.blocks, prior=self._prior_gram(des))
        n = des.y.size
        aic = [n * np.log(max(c.rss, 1e-300) / n) + 2 * c.n_terms for c in fwd.candidates_]
        i = int(np.argmin(aic))
        return fwd.candidates_[i], float(aic[i])

    def _profile_objective(self, library: AFMLibrary, a0: float) -> float:
        """Best AIC over short forward-selected supports at ``a0`` (smaller is better)."""
        return self._short_models(library, a0)[1]

    def _support_rss(self, lib: AFMLibrary, a0: float) -> float:
        """Residual sum of squares of the full support of ``lib`` at ``a0`` (inf: infeasible)."""
        des = self._design(lib, a0)
        G, b = self._gram(des)
        try:
            c = self._template().refit_gram(G, b, np.ones(G.shape[0], bool))[0]
        except Exception:  # noqa: BLE001 - infeasible corner
            return np.inf
        r = des.y - des.theta @ c
        return float(r @ r)

    def _refit(self, des: _Design, support: NDArray[np.bool_]) -> FloatArray:
        G, b = self._gram(des)
        return self._template().refit_gram(G, b, support)[0]

    def _cv(self, lib: AFMLibrary, a0: float) -> FloatArray:
        """Rolling-CV errors (per fold) of the full support of ``lib`` at ``a0``."""
        des = self._design(lib, a0)
        supp = np.ones(des.theta.shape[1], bool)
        return cv_errors(self._template(), des.theta, des.y, self._bound.blocks, supp,
                         prior=self._prior_gram(des))

    def _exponent_profile(self, model: IdentifiedModel,
                          summary: dict[str, Any]) -> FloatArray | None:
        """Profile residual of the interaction exponent, shape (n_p, 2): ``(p, min RSS)``.

        The dominant ``delta^p`` of the chosen support is swept over ``p`` in 0.5 ... 4 with
        the other terms kept; ``a0`` and all coefficients are re-fitted at every ``p`` (``a0``
        on a grid over its range), so the profile follows the (a0, exponent, stiffness)
        valley. None when the model has no contact term.
        """
        expo = summary.get("interaction_exponent")
        lib = self._lib_final
        js = [j for j, t in enumerate(lib.terms)
              if isinstance(t, Indentation) and expo is not None and t.p == expo]
        if not js:
            return None
        j = js[0]
        lo, hi = self._a0_range
        a0s = np.unique(np.concatenate([np.geomspace(lo, hi, 10), [model.a0]]))
        ps = np.unique(np.concatenate([np.arange(0.5, 4.001, 0.25), [expo]]))
        out = []
        for p in ps:
            lp = lib.replace(j, Indentation(float(p)))
            out.append((float(p), min(self._support_rss(lp, a) for a in a0s)))
        return np.array(out)

    def _refine(self, lib: AFMLibrary, a0: float) -> tuple[AFMLibrary, float]:
        """Nelder--Mead on (a0, exponents, decay lengths) of a fixed support."""
        params: list[tuple[int, str, float]] = [(-1, "a0", a0)]
        for j, t in enumerate(lib.terms):
            if isinstance(t, Indentation | IndentationRate):
                params.append((j, "p", t.p))
            elif isinstance(t, ExponentialDamping):
                params.append((j, "decay_length", t.decay_length))
        x0 = np.array([v for _, _, v in params], float)

        def build(v: FloatArray) -> tuple[AFMLibrary, float] | None:
            new = lib
            for (j, name, _), val in zip(params[1:], v[1:], strict=True):
                if name == "p":
                    p0 = lib.terms[j].p
                    if not (0.5 <= val <= 4.0 and abs(val - p0) <= 0.5):
                        return None
                    t = lib.terms[j]
                    new = new.replace(j, type(t)(float(val)) if isinstance(t, Indentation)
                                      else IndentationRate(float(val), t.l))
                else:
                    if not 1e-3 <= val <= 2.0:
                        return None
                    new = new.replace(j, ExponentialDamping(float(val)))
            if not (v[0] > 0 and self._a0_range[0] <= v[0] <= self._a0_range[1]):
                return None
            return new, float(v[0])

        def obj(v: FloatArray) -> float:
            built = build(v)
            if built is None:
                return 1e300
            des = self._design(*built)
            G, b = self._gram(des)
            try:
                c = self._template().refit_gram(G, b, np.ones(G.shape[0], bool))[0]
            except Exception:  # noqa: BLE001 - infeasible corner of the search
                return 1e300
            r = des.y - des.theta @ c
            return float(r @ r)

        step = np.where(x0 != 0, 0.05 * np.abs(x0), 0.01)
        simplex = np.vstack([x0] + [x0 + np.eye(x0.size)[i] * step[i] for i in range(x0.size)])
        res = minimize(obj, x0, method="Nelder-Mead",
                       options={"initial_simplex": simplex, "xatol": 1e-4, "fatol": 1e-12,
                                "maxiter": 200 * x0.size})
        best = build(res.x) if res.fun <= obj(x0) else None
        return best if best is not None else (lib, a0)

    def _bag(self, des: _Design, support: NDArray[np.bool_]) -> FloatArray:
        """Moving-block bootstrap over row blocks; every refit keeps boxes and priors."""
        rng = np.random.default_rng(self.seed)
        blocks = self._bound.blocks
        nb = len(blocks)
        G0, b0 = self._prior_gram(des)
        Gb = [des.theta[a:z].T @ des.theta[a:z] for a, z in blocks]
        bb = [des.theta[a:z].T @ des.y[a:z] for a, z in blocks]
        out = []
        for _ in range(self.n_bootstrap):
            pick = rng.integers(0, nb, nb)
            G = sum(Gb[i] for i in pick) + G0
            b = sum(bb[i] for i in pick) + b0
            try:
                out.append(self._template().refit_gram(G, b, support)[0])
            except Exception:  # noqa: BLE001 - an infeasible resample is skipped
                continue
        return np.array(out) if out else np.empty((0, des.theta.shape[1]))

    def _to_model(self, library: AFMLibrary, a0: float, coef: FloatArray, *,
                  bands: FloatArray | None = None,
                  info: dict[str, Any] | None = None) -> IdentifiedModel:
        cal = self._cal
        keep = np.asarray(coef[_N_LIN:]) != 0
        lib = library.subset(keep) if keep.any() else None
        cf = np.asarray(coef[_N_LIN:])[keep]
        if lib is None:  # no force term: an explicit zero constant keeps the model valid
            from .library import Constant
            lib, cf = AFMLibrary([Constant()]), np.zeros(1)
            bands = None
        elif bands is not None:
            bands = bands[:, keep]
        bc, bs = float(coef[2]), float(coef[3])
        amp = math.hypot(bc, bs)
        phase = self._rotation + math.atan2(bs, bc)
        g = cal.gap if np.isscalar(cal.gap) else float(np.mean(cal.gap))
        return IdentifiedModel(library=lib, coefficients=cf, stiffness=-float(coef[1]),
                               damping=-float(coef[0]), drive_amplitude=amp,
                               drive_phase=phase, omega=cal.omega, a0=float(a0),
                               gap=float(g), scales=cal.scales, coefficient_bands=bands,
                               info=info or {})

    def _state_error(self, model: IdentifiedModel) -> float:
        """Held-out orbit error: mean NRMSE of ``x``, ``x'``, ``x''`` (design.md section 4).

        The model is simulated from the measured (denoised) state at the start of the held-out
        span; the reference ``x``, ``x'``, ``x''`` come from denoising the held-out samples on
        their own (never used in fitting), so measurement noise does not set a floor.
        """
        cal = self._cal
        i0 = self.heldout_start_
        n_h = min(cal.n_samples - i0, int(self.max_heldout_periods * cal.samples_per_period))
        x0, v0 = self._initial_state(i0)
        dtau = float(cal.tau[1] - cal.tau[0])
        sub = self.substeps or max(1, math.ceil(400 / cal.samples_per_period))
        xs, vs = model.simulate(x0, v0, tau0=float(cal.tau[i0]), dtau=dtau, n_samples=n_h,
                                substeps=sub)
        if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(vs))):
            return 1.0
        tau = cal.tau[i0:i0 + n_h]
        gap = np.broadcast_to(np.asarray(cal.gap, float), cal.tau.shape)[i0:i0 + n_h]
        acc = (-model.damping * vs - model.stiffness * xs
               + model.drive_amplitude * np.cos(model.omega * tau - model.drive_phase)
               - model.force(gap - xs, -vs, xs))
        ref = self._heldout_reference()
        errs = [nrmse(a, b[:n_h]) for a, b in zip((xs, vs, acc), ref, strict=True)]
        return float(min(np.mean(errs), 1.0))

    def _heldout_reference(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Denoised held-out ``x``, ``x'``, ``x''`` (cached)."""
        if getattr(self, "_ref_cache", None) is not None:
            return self._ref_cache
        cal = self._cal
        i0 = self.heldout_start_
        tau, x = cal.tau[i0:], cal.x[i0:]
        hf = self._den.harmonic_fit
        if hf is not None and self.periodic_:
            h = fit_harmonics(tau, x, cal.omega, n_harmonics=min(hf.n_harmonics,
                                                                 max(x.size // 4 - 1, 1)))
            ref = (h.evaluate(tau), h.evaluate(tau, 1), h.evaluate(tau, 2))
        else:
            w = default_window(cal.samples_per_period)
            ref = savgol_derivatives(x, float(tau[1] - tau[0]), window=w)
        self._ref_cache = ref
        return ref

    def _initial_state(self, i0: int) -> tuple[float, float]:
        hf = self._den.harmonic_fit
        cal = self._cal
        if hf is not None:
            t = cal.tau[i0]
            return float(hf.evaluate(np.array([t]))[0]), float(hf.evaluate(np.array([t]), 1)[0])
        w = default_window(cal.samples_per_period)
        a = max(i0 - 2 * w, 0)
        b = min(i0 + 2 * w, cal.n_samples)
        xs, xd, _ = savgol_derivatives(cal.x[a:b], float(cal.tau[1] - cal.tau[0]), window=w)
        return float(xs[i0 - a]), float(xd[i0 - a])

    def _force_error(self, model: IdentifiedModel, f_true: FloatArray) -> float:
        d = self._den
        gap = self._bound_gap()
        f = model.force(np.asarray(gap - d.x, float), -d.v, d.x)
        return float(nrmse(f, f_true))

    # ------------------------------------------------------------------ outputs
    def _full_state(self) -> tuple[FloatArray, FloatArray]:
        cal = self._cal
        if self.periodic_:
            hf = self._den.harmonic_fit
            assert hf is not None
            return hf.evaluate(cal.tau), hf.evaluate(cal.tau, 1)
        w = default_window(cal.samples_per_period)
        xs, xd, _ = savgol_derivatives(cal.x, float(cal.tau[1] - cal.tau[0]), window=w)
        return xs, xd

    def _outputs(self, model: IdentifiedModel, samples: FloatArray | None,
                 true_force: FloatArray | None) -> None:
        cal = self._cal
        xs, vs = self._full_state()
        gap = np.broadcast_to(np.asarray(cal.gap, float), xs.shape)
        z, zd = gap - xs, -vs
        force = model.force(z, zd, xs)
        self.state_x_, self.state_v_ = xs, vs
        self.force_ = force
        lo = hi = np.full_like(force, np.nan)
        if samples is not None and len(samples) >= 5:
            kinds, p1, p2 = self._lib_final.encode()  # bagged samples use this layout
            hf = self._den.harmonic_fit
            if self.periodic_ and hf is not None:
                # periodic: the bands are functions of the drive phase; evaluate on one
                # period and interpolate (exact up to the 4096-point phase grid)
                m = 4096
                ph = 2 * np.pi * np.arange(m + 1) / m
                tg = ph / hf.base_frequency
                xg, vg = hf.evaluate(tg), hf.evaluate(tg, 1)
                gz, gzd = float(np.mean(gap)) - xg, -vg
                fs = np.array([force_series(kinds, p1, p2, np.ascontiguousarray(c[_N_LIN:]),
                                            model.a0, gz, gzd, xg) for c in samples])
                lo_g, hi_g = np.percentile(fs, [2.5, 97.5], axis=0)
                phase = np.mod(hf.base_frequency * cal.tau, 2 * np.pi)
                lo, hi = np.interp(phase, ph, lo_g), np.interp(phase, ph, hi_g)
            else:
                fs = np.array([force_series(kinds, p1, p2, np.ascontiguousarray(c[_N_LIN:]),
                                            model.a0, np.ascontiguousarray(z),
                                            np.ascontiguousarray(zd), xs) for c in samples])
                lo, hi = np.percentile(fs, [2.5, 97.5], axis=0)
        self.force_lo_, self.force_hi_ = lo, hi
        self.summary_ = summarize(model, z=z, zdot=zd, force=force, cal=cal,
                                  state_error=self._state_error(model))
        self.exponent_profile_ = self._exponent_profile(model, self.summary_)
        if self.exponent_profile_ is not None:
            n_rows = self._design(self._lib_final, model.a0).y.size
            iv = _profile_interval(self.exponent_profile_, n_rows)
            self.summary_["interaction_exponent_interval"] = iv
            grid = self.exponent_profile_[:, 0]
            self.summary_["interaction_exponent_bounded"] = bool(
                iv[0] > grid.min() + 1e-9 and iv[1] < grid.max() - 1e-9)
        if true_force is not None:
            self.summary_["force_nrmse_vs_truth"] = float(nrmse(force, true_force))

    # ------------------------------------------------------------------ convenience
    @property
    def equation_(self) -> str:
        return self.model_.equation()
