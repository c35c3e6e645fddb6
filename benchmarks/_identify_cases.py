"""Cases, cached traces, truth and baselines of ``bench_identify_accuracy.py``.

Traces are simulated with the project's simulator through the Hydra configs of ``conf/``
(``conf/simulate.yaml`` composed with overrides, as ``scripts/simulate.py`` does) and cached
under ``outputs/bench_cache/identify/`` (a file that exists is reused; files are written
atomically by the simulator).

Baselines (all dimensionless: lengths / ``L_ref``, time ``tau = omega0 t``, force / ``k L_ref``):

- transfer-function inversion (`afmlearn.identify.transfer.transfer_function_force`) with a
  given drive and a derivative estimator;
- plain pysindy STLSQ and pysindy ConstrainedSR3 (equality constraints ``K = 1``, ``D = 1/Q``,
  weighted l0) on one regression matrix: target ``x''`` (Savitzky--Golay, default window),
  columns ``[x', x, cos, sin, -theta_j]`` with ``theta_j`` the terms of
  ``AFMLibrary.standard()`` evaluated on the Savitzky--Golay state at the TRUE ``a0`` (these
  baselines have no ``a0`` search of their own; giving them the truth favours them). The
  coefficient of ``-theta_j`` is the force coefficient ``c_j`` of ``F_ts = sum c_j theta_j``.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from afmlearn.identify.library import AFMLibrary, TermInput
from afmlearn.identify.train import true_model
from afmlearn.io import Trace, read_trace
from afmlearn.metrics import force_accuracy
from afmlearn.preprocess import Calibrated, default_window, savgol_derivatives

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "outputs" / "bench_cache" / "identify"

FloatArray = NDArray[np.float64]

#: overrides of the forces that need their own set-up (as tests/afmlearn/test_simulate.py)
FORCE_SETUP: dict[str, tuple[str, ...]] = {
    "lj": ("cantilever=soft_lj", "excitation.free_amplitude_ratio=0.1"),
}
#: free-lever-to-periodic settling: >= 8 Q drive periods (Q = 443 for the tapping lever)
SETTLE_PERIODS = 3500


@dataclass(frozen=True)
class Case:
    """One simulated trace: force config, noise, sampling, length, extra overrides."""

    force: str
    noise: float
    spp: int
    periods: int
    extra: tuple[str, ...] = ()
    seed: int = 0
    label: str = ""

    @property
    def key(self) -> str:
        ex = "_".join(e.replace("=", "-").replace(".", "") for e in self.extra)
        return (f"{self.force}_n{self.noise:g}_spp{self.spp}_p{self.periods}_s{self.seed}"
                + (f"_{ex}" if ex else ""))

    def overrides(self, output: Path) -> list[str]:
        return [f"force={self.force}", *FORCE_SETUP.get(self.force, ()), *self.extra,
                f"noise.level={self.noise}", f"scenario.samples_per_period={self.spp}",
                f"scenario.n_periods={self.periods}",
                f"scenario.settle_periods={SETTLE_PERIODS}", f"seed={self.seed}",
                f"output={output}", "progress=false", "labels=true"]


def trace_for(case: Case) -> tuple[Path, float]:
    """Path of the cached trace of ``case`` (simulated if missing) and simulation time [s]."""
    from hydra import compose, initialize_config_dir

    from afmlearn.simulate import simulate

    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"{case.key}.h5"
    if path.exists():
        return path, 0.0
    t0 = time.perf_counter()
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("simulate", overrides=case.overrides(path))
    simulate(cfg)
    return path, time.perf_counter() - t0


@dataclass
class Truth:
    """The simulator's truth on one trace (dimensionless, L_ref = the trace's rest gap)."""

    force: FloatArray          # (n,) F_ts / (k L_ref)
    z: FloatArray              # (n,) true instantaneous gap / L_ref
    a0: float                  # contact onset / L_ref (LJ: zero of the force)
    drive_cos: float           # true B_c of B_c cos(Omega tau) + B_s sin(Omega tau)
    drive_sin: float
    model_json: dict[str, Any] = field(default_factory=dict)


def truth_of(path: Path, cal: Calibrated) -> tuple[Trace, Truth]:
    """Read the labels of a simulated trace and express them in the calibration's units."""
    lab_trace = read_trace(path, labels=True)
    lab = lab_trace.labels
    assert lab is not None
    sc = cal.scales
    force = np.asarray(lab.force_n, float) / sc.force
    z = np.asarray(lab.extra["tip_sample_gap_m"], float) / sc.length
    tm = true_model(lab.model, omega=cal.omega, quality_factor=cal.quality_factor)
    length_sim = float(lab.model["calibration"]["length_m"])
    a0 = tm.a0 * length_sim / sc.length if tm is not None else math.nan
    x_true = np.asarray(lab.modal_m, float).sum(axis=0) / sc.length
    bc, bs = true_drive(cal.tau, x_true, force, omega=cal.omega, q=cal.quality_factor)
    return read_trace(path), Truth(force=force, z=z, a0=a0, drive_cos=bc, drive_sin=bs,
                                   model_json=lab.model)


def true_drive(tau: FloatArray, x: FloatArray, force: FloatArray, *, omega: float,
               q: float) -> tuple[float, float]:
    """``(B_c, B_s)`` from the noise-free deflection and true force (single mode).

    The fundamental of ``x'' + x'/Q + x + F_ts = B_c cos(Omega tau) + B_s sin(Omega tau)``:
    with ``X_1 = 2 <x e^{-i Omega tau}>`` over whole periods,
    ``B_c - i B_s = (1 - Omega^2 + i Omega/Q) X_1 + F_1``.
    """
    spp = 2 * np.pi / (omega * float(tau[1] - tau[0]))
    m = int(round(int(x.size // spp) * spp))
    e = np.exp(-1j * omega * tau[:m])
    x1 = 2 * np.mean(x[:m] * e)
    f1 = 2 * np.mean(force[:m] * e)
    s = (1 - omega**2 + 1j * omega / q) * x1 + f1
    return float(s.real), float(-s.imag)


def accuracy(f_pred: FloatArray, truth: Truth) -> dict[str, dict[str, float]]:
    """`afmlearn.metrics.force_accuracy` against the truth (true gap ``z``, true ``a0``)."""
    return force_accuracy(np.asarray(f_pred, float), truth.force, truth.z, truth.a0)


# ---------------------------------------------------------------------------- regression matrix
@dataclass
class Matrix:
    """The baselines' regression problem on (decimated) rows.

    Columns scaled to unit RMS, and rows by ``1/sqrt(r)`` (mean-square objective).
    """

    theta: FloatArray          # (r, 4 + p) scaled columns [x', x, cos, sin, -theta_j]
    y: FloatArray              # (r,) x''
    scale: FloatArray          # (4 + p,) RMS of each unscaled column
    names: list[str]
    library: AFMLibrary
    state: TermInput           # SG state on every sample (for the force)
    _full: FloatArray | None = None

    @property
    def full(self) -> FloatArray:
        """Library terms on every sample, shape (n, p) (computed once)."""
        if self._full is None:
            self._full = self.library.evaluate(self.state)
        return self._full


def regression_matrix(cal: Calibrated, a0: float, *, max_rows: int = 200_000) -> Matrix:
    """Build the baselines' matrix (see the module docstring); rows decimated to ``max_rows``."""
    w = default_window(cal.samples_per_period)
    xs, xd, xdd = savgol_derivatives(cal.x, float(cal.tau[1] - cal.tau[0]), window=w)
    lib = AFMLibrary.standard()
    gap = np.broadcast_to(np.asarray(cal.gap, float), xs.shape)
    state = TermInput(z=gap - xs, zdot=-xd, x=xs, a0=a0)
    edge = w  # savgol's polynomial edge fits are worse: drop them from the fit
    idx = np.arange(edge, cal.n_samples - edge)
    step = max(1, idx.size // max_rows)
    idx = idx[::step]
    sub = TermInput(z=state.z[idx], zdot=state.zdot[idx], x=xs[idx], a0=a0)
    ph = cal.omega * cal.tau[idx]
    lin = np.stack([xd[idx], xs[idx], np.cos(ph), np.sin(ph)], axis=1)
    theta = np.concatenate([lin, -lib.evaluate(sub)], axis=1)
    scale = np.sqrt(np.mean(theta**2, axis=0))
    scale[scale == 0] = 1.0
    names = ["x'", "x", "cos(Omega tau)", "sin(Omega tau)", *lib.names]
    # rows / sqrt(r): the squared residual becomes a mean, so SR3's relaxation nu and the
    # thresholds do not depend on the number of rows (X^T X ~ identity-sized)
    r = math.sqrt(idx.size)
    return Matrix(theta=theta / scale / r, y=xdd[idx] / r, scale=scale, names=names,
                  library=lib, state=state)


def _force_of(mat: Matrix, coef_scaled: FloatArray) -> FloatArray:
    c = np.asarray(coef_scaled, float).reshape(-1) / mat.scale
    return mat.full @ c[4:]


def _terms(mat: Matrix, coef_scaled: FloatArray) -> dict[str, float]:
    c = np.asarray(coef_scaled, float).reshape(-1) / mat.scale
    return {n: float(v) for n, v in zip(mat.names, c, strict=True) if v != 0}


#: thresholds of the baselines' sweeps: RMS contribution of a term to ``x''`` (the drive and
#: ``D x'`` contribute ~2e-3 on the tapping lever, the contact force ~1e-3 to 1e-2; at the top
#: every force term is dropped)
THRESHOLDS = np.geomspace(1e-5, 1.0, 11)


def stlsq_baseline(mat: Matrix, truth: Truth) -> dict[str, Any]:
    """Plain pysindy STLSQ over `THRESHOLDS`; the best by whole-trace force NRMSE is reported."""
    from pysindy.optimizers import STLSQ

    best: dict[str, Any] | None = None
    sweep = []
    for t in THRESHOLDS:
        opt = STLSQ(threshold=float(t), alpha=1e-8, max_iter=20)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt.fit(mat.theta, mat.y)
        f = _force_of(mat, opt.coef_)
        acc = accuracy(f, truth)
        sweep.append((float(t), acc["whole"]["nrmse"]))
        if best is None or acc["whole"]["nrmse"] < best["acc"]["whole"]["nrmse"]:
            best = {"threshold": float(t), "acc": acc, "terms": _terms(mat, opt.coef_)}
    assert best is not None
    best["sweep"] = sweep
    return best


def constrained_sr3_baseline(mat: Matrix, truth: Truth, *, q: float) -> dict[str, Any]:
    """pysindy ConstrainedSR3, equality constraints ``K = 1``, ``D = 1/Q``, weighted l0.

    The l0 weight of the four lever/drive columns is 0 (pysindy thresholds a constrained
    ``-1/Q`` otherwise); the force terms get ``lambda = t^2 / (2 nu)`` (pysindy's l0
    convention: the prox zeroes ``|w| < t``) with ``t`` swept over `THRESHOLDS` in the
    scaled columns' units. Constraints are written for the scaled coefficients
    (``c'_x = -rms(x)``, ``c'_x' = -rms(x')/Q``), so they hold exactly on the unscaled ones.
    """
    from pysindy.optimizers import ConstrainedSR3

    p = mat.theta.shape[1]
    lhs = np.zeros((2, p))
    lhs[0, 0] = 1.0
    lhs[1, 1] = 1.0
    rhs = np.array([-mat.scale[0] / q, -mat.scale[1]])
    nu = 1.0
    best: dict[str, Any] | None = None
    sweep = []
    for t in THRESHOLDS:
        lam = np.full((1, p), t**2 / (2 * nu))
        lam[0, :4] = 0.0
        opt = ConstrainedSR3(reg_weight_lam=lam, regularizer="weighted_l0", relax_coeff_nu=nu,
                             constraint_lhs=lhs, constraint_rhs=rhs,
                             equality_constraints=True, max_iter=100, tol=1e-8)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt.fit(mat.theta, mat.y)
        f = _force_of(mat, opt.coef_)
        acc = accuracy(f, truth)
        sweep.append((float(t), acc["whole"]["nrmse"]))
        if best is None or acc["whole"]["nrmse"] < best["acc"]["whole"]["nrmse"]:
            best = {"threshold": float(t), "acc": acc, "terms": _terms(mat, opt.coef_)}
    assert best is not None
    best["sweep"] = sweep
    return best


# ---------------------------------------------------------------------------- set-point series
@dataclass(frozen=True)
class SeriesCase:
    """A set-point series: steady records at the rest gaps ``gaps`` (/ L_ref), same drive.

    Every row is a ``scenario=steady`` simulation at its own gap (settled from the free orbit,
    as an approach reaches that gap) with its own noise seed; the drive phase at each row's
    first sample (design.md section 2 convention) is kept with the cached row.
    """

    force: str
    noise: float
    spp: int
    periods: int
    gaps: tuple[float, ...]
    extra: tuple[str, ...] = ()
    seed: int = 0
    settle: int = SETTLE_PERIODS
    #: free amplitude / the lever's rest-gap unit per row (empty: the config's for every row);
    #: rows at another free amplitude reach other indentations
    amplitudes: tuple[float, ...] = ()

    def row_case(self, i: int) -> Case:
        amp = (f"excitation.free_amplitude_ratio={self.amplitudes[i]:.6g}",) \
            if self.amplitudes else ()
        return Case(self.force, self.noise, self.spp, self.periods,
                    extra=(*self.extra, *amp, f"scenario.gap={self.gaps[i]:.6g}"),
                    seed=1000 * self.seed + i)


@dataclass
class SeriesData:
    """Rows of a simulated series with their truth, in ONE length unit (the mean rest gap).

    ``traces`` carry ``drive_phase_rad`` when the Trace supports it; ``phases`` (n_obs,) is the
    drive phase at each row's first sample either way. Truth arrays have shape (n_obs, n).
    """

    traces: list[Trace]
    phases: FloatArray
    length_m: float
    force: FloatArray
    z: FloatArray
    a0: float


def series_for(case: SeriesCase) -> SeriesData:
    """Simulate (or read from the cache) every row of ``case``; truth in the common unit."""
    import dataclasses
    import json

    from hydra import compose, initialize_config_dir

    from afmlearn.simulate import simulate

    CACHE.mkdir(parents=True, exist_ok=True)
    traces, phases, labelled = [], [], []
    for i in range(len(case.gaps)):
        rc = case.row_case(i)
        # a random fraction of a period on top of the settling: a random drive phase per row
        settle = case.settle + float(np.random.default_rng([case.seed, i]).uniform())
        rc = Case(rc.force, rc.noise, rc.spp, rc.periods, seed=rc.seed,
                  extra=(*rc.extra, f"scenario.settle_periods={settle:.6f}"))
        path = CACHE / f"{rc.key}.h5"
        side = path.with_suffix(".json")
        if not (path.exists() and side.exists()):
            ov = [o for o in rc.overrides(path)
                  if o != f"scenario.settle_periods={SETTLE_PERIODS}"]
            with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
                cfg = compose("simulate", overrides=ov)
            _, objects = simulate(cfg)
            phase0 = float(np.asarray(objects["result"].phase).reshape(-1)[0])
            side.write_text(json.dumps({"drive_phase_rad": phase0}))
        phase = float(json.loads(side.read_text())["drive_phase_rad"])
        tr = read_trace(path)
        if "drive_phase_rad" in {f.name for f in dataclasses.fields(tr)}:
            tr = dataclasses.replace(tr, drive_phase_rad=phase)
        traces.append(tr)
        phases.append(math.remainder(phase, 2 * math.pi))
        labelled.append(read_trace(path, labels=True))
    length = float(np.mean([float(t.gap_m) for t in traces]))
    k = traces[0].spring_constant_n_per_m
    lab0 = labelled[0].labels
    assert lab0 is not None
    tm = true_model(lab0.model, omega=1.0, quality_factor=traces[0].quality_factor)
    a0_m = tm.a0 * float(lab0.model["calibration"]["length_m"]) if tm is not None else math.nan
    force = np.stack([np.asarray(t.labels.force_n, float) for t in labelled]) / (k * length)
    z = np.stack([np.asarray(t.labels.extra["tip_sample_gap_m"], float)
                  for t in labelled]) / length
    return SeriesData(traces=traces, phases=np.array(phases), length_m=length, force=force,
                      z=z, a0=a0_m / length)
