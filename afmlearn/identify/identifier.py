"""`ForceIdentifier`: constrained sparse regression of the tip--sample force from deflection.

The estimator holds settings only; :meth:`ForceIdentifier.fit` builds an immutable problem,
runs a short sequence of frozen stage objects on it and assigns the fitted attributes once at
the end. Two problems, one pattern:

- **one orbit** (a trace, one row, a ramp; physics.md section 5):
  :func:`~afmlearn.identify.single_problem.build_orbit_problem` splits off the last
  ``heldout_fraction`` of the periods (never fitted; it scores the candidates), denoises (Fourier
  series when periodic, Savitzky--Golay otherwise) and projects the equation of motion on rows
  (:class:`HarmonicBalance` / :class:`WeakForm`: no derivative of noisy data); then
  :func:`~afmlearn.identify.single.fit_orbit` runs noise scale -> ``a0`` profile -> drive
  phase -> selection (SR3 grid + forward path, ``a0`` re-profiled) -> Pareto choice (CV error,
  held-out state error, training force error) -> refinement -> bagging; the exponent profile
  and summary are :mod:`afmlearn.identify.single_outputs`;
- **an experiment of several observations**: :func:`~afmlearn.identify.problem.build_problem`
  and :func:`~afmlearn.identify.joint.fit_joint` (one law shared by every set-point).

Boxes and calibration priors on ``K``, ``D``, ``B`` (:class:`CalibrationConstraints`) and the
physical signs of the terms hold in every fit of both paths.
"""

from __future__ import annotations

import logging
import math
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io import Experiment, Trace
from afmlearn.preprocess import Calibrated, calibrate, check_trace

from .constraints import CalibrationConstraints
from .drive import AbstractDrivePhase
from .fixed_exponent import fixed_exponent_law
from .joint import (
    DEFAULT_OUTPUT_ERROR,
    Bagging,
    ContactOnsetProfile,
    ExponentProfile,
    OrbitOffsets,
    Refinement,
    SupportSelection,
)
from .library import AFMLibrary
from .output_error import OutputErrorStage
from .projection import AbstractProjection, HarmonicBalance
from .single import (
    DrivePhaseChoice,
    HeldoutStateError,
    OrbitExponentProfile,
    OrbitOnsetProfile,
    OrbitRefinement,
    OrbitSelection,
    ParetoChoice,
    fit_orbit,
    orbit_model,
)
from .single_outputs import orbit_force, orbit_summary
from .single_problem import N_LIN, build_orbit_problem
from .summary import force_vs_gap, summarize

log = logging.getLogger(__name__)

__all__ = ["ForceIdentifier", "LINEAR_TERMS", "force_vs_gap", "summarize"]

FloatArray = NDArray[np.float64]

#: names of the four lever/drive columns that precede the force terms
LINEAR_TERMS = ("x'", "x", "cos(Omega tau)", "sin(Omega tau)")


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
    output_error : OutputErrorStage or None
        The joint fit's output-error stage (default ``OutputErrorStage()``: the law's own
        periodic orbits against every observation's harmonics); None: the equation-error
        law with bootstrap bands and :class:`ExponentProfile`.
    seed : int
        Seed of the bootstrap.
    progress : bool
        Log the stages (logger ``afmlearn.identify.identifier``, level INFO; the Hydra scripts'
        job logging shows INFO on the console and in the run's log file).

    Attributes
    ----------
    calibrated_ : Calibrated or None
        The single orbit's calibration (None after a joint fit).
    orbit_ : OrbitResult or None
        What the single-orbit stages found (:func:`afmlearn.identify.single.fit_orbit`);
        None after a joint fit.
    joint_ : JointResult or None
        What the joint stages found (:func:`afmlearn.identify.joint.fit_joint`); None after
        a single-orbit fit.
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
        Identified ``F_ts`` [k L_ref] on every sample and its 95 % band (NaN where undefined;
        a joint fit: shape (n_obs, n), the output-error band from the exponent's profile,
        :mod:`afmlearn.identify.force_band`).
    fixed_exponent_ : FixedExponentLaw or None
        When the data do not bound the contact exponent: the law quoted at the sphere's 1.5
        with its force and band on the same samples (:mod:`afmlearn.identify.fixed_exponent`);
        None otherwise.
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
                 output_error: OutputErrorStage | None = DEFAULT_OUTPUT_ERROR,
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
        self.output_error = output_error
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
        if self.output_error is not None and not isinstance(self.output_error,
                                                            OutputErrorStage):
            raise ValueError(f"output_error must be an OutputErrorStage or None, "
                             f"got {self.output_error!r}")
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
            log.info(msg)

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
        warns = [] if problem.drive_amplitude is not None else [
            "no free data (free_deflection_m or free_amplitude_m): the drive amplitude is not "
            "constrained"]
        res = fit_joint(problem, library, drive=self.drive_phase,
                        onset=ContactOnsetProfile(n_a0=self.n_a0),
                        selection=SupportSelection(max_terms=self.max_terms),
                        refinement=Refinement() if self.refine else None,
                        bagging=Bagging(n_bootstrap=self.n_bootstrap, seed=self.seed),
                        exponent=self.exponent_profile or ExponentProfile(),
                        offsets=OrbitOffsets(), output_error=self.output_error,
                        log=self._log)
        n_lin = res.problem.n_lin
        bands = (None if res.samples.shape[0] < 5
                 else np.percentile(res.samples[:, n_lin:], [2.5, 97.5], axis=0))
        chosen = res.candidates[res.knee_index]
        model = joint_model(res, res.coef, res.library, res.a0, bands=bands, info={
            "n_terms": chosen.n_terms, "cv_error": chosen.cv_error,
            "projection": "HarmonicBalance", "periodic": True, "joint": True,
            "n_observations": res.problem.n_obs})
        forces = joint_force(res)
        # -- the fitted attributes, assigned once
        self.warnings_ = warns
        self.joint_, self.orbit_, self.calibrated_ = res, None, None
        self.model_ = model
        self.ic_model_ = joint_model(res, res.ic_coef, res.selection_library,
                                     res.selection_a0)
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
        self.summary_ = joint_summary(res, model, forces)
        self.drive_phase_candidates_ = []
        self.fixed_exponent_ = fixed_exponent_law(self)
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
            pipeline (:mod:`afmlearn.identify.single`). Labels are never read.
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
        return self._fit_orbit(cal, true_force)

    def _fit_orbit(self, cal: Calibrated, true_force: FloatArray | None) -> ForceIdentifier:
        """Single-orbit fit: problem, stages, outputs; the fitted attributes set once here."""
        n = cal.n_samples
        if true_force is not None:
            true_force = np.asarray(true_force, float)
            if true_force.shape != (n,):
                raise ValueError(f"true_force must have shape ({n},), got {true_force.shape}")
        library = AFMLibrary.standard() if self.library is None else self.library
        self._log("denoising")
        problem = build_orbit_problem(
            cal, constraints=self.constraints or CalibrationConstraints(),
            projection=self.projection, heldout_fraction=self.heldout_fraction,
            n_folds=self.n_folds, max_harmonics=self.max_harmonics,
            min_harmonics=self.min_harmonics, thresholds=self.thresholds, nus=self.nus,
            n_a0=self.n_a0,
            a0_range_m=None if self.a0_range_m is None else tuple(self.a0_range_m),
            physical_signs=self.physical_signs)
        state = HeldoutStateError(max_heldout_periods=self.max_heldout_periods,
                                  substeps=self.substeps)
        res = fit_orbit(problem, library, onset=OrbitOnsetProfile(), drive=DrivePhaseChoice(),
                        selection=OrbitSelection(n_folds=self.n_folds,
                                                 max_terms=self.max_terms),
                        choice=ParetoChoice(state=state),
                        refinement=OrbitRefinement() if self.refine else None,
                        bagging=(Bagging(n_bootstrap=self.n_bootstrap, seed=self.seed)
                                 if self.n_bootstrap else None),
                        true_force=true_force, log=self._log)
        pb, chosen = res.problem, res.chosen
        bands = (None if res.samples is None
                 else np.percentile(res.samples[:, N_LIN:], [2.5, 97.5], axis=0))
        model = orbit_model(pb, res.library, res.a0, res.coef, bands=bands, info={
            "threshold": chosen.threshold, "nu": chosen.nu, "n_terms": chosen.n_terms,
            "cv_error": chosen.cv_error, "scores": dict(chosen.scores),
            "projection": type(pb.projection).__name__, "periodic": pb.periodic,
        })
        sel = res.selection
        forces = orbit_force(pb, model, res.library, res.samples)
        summary, expo = orbit_summary(res, model, forces, state=state,
                                      exponent=OrbitExponentProfile(), true_force=true_force)
        # -- the fitted attributes, assigned once
        self.warnings_ = _calibration_warnings(cal)
        self.joint_, self.orbit_, self.calibrated_ = None, res, cal
        self.heldout_start_ = pb.heldout_start
        self.periodic_ = pb.periodic
        self.projection_ = pb.projection
        self.a0_profile_ = res.a0_profile
        self.drive_phase_candidates_ = res.drive_phase_candidates
        self.search_ = sel.search
        self.candidates_ = res.candidates
        self.objectives_ = res.objectives
        self.knee_index_, self.ic_index_ = res.knee_index, res.ic_index
        self.ic_model_ = orbit_model(pb, sel.design.library, sel.design.a0,
                                     res.candidates[res.ic_index].coef[0])
        self.refined_ = res.refined
        self.model_ = model
        self.force_, self.force_lo_, self.force_hi_ = forces["force"], forces["lo"], forces["hi"]
        self.state_x_, self.state_v_ = forces["x"], forces["v"]
        self.summary_ = summary
        self.exponent_profile_ = expo
        self.fixed_exponent_ = fixed_exponent_law(self)
        return self

    # ------------------------------------------------------------------ convenience
    @property
    def equation_(self) -> str:
        return self.model_.equation()


def _calibration_warnings(cal: Calibrated) -> list[str]:
    """What the calibration had to assume (shown with the result)."""
    out = []
    if cal.excitation_assumed:
        out.append("excitation not recorded in the file: tip excitation assumed")
    if cal.drive_amplitude is None:
        out.append("no free data (free_deflection_m or free_amplitude_m): the drive amplitude "
                   "is not constrained")
    if cal.excitation == "base":
        out.append("base excitation: the dither's own contribution to the gap is neglected "
                   "(it is below 1 % of the gap for typical dithers)")
    return out
