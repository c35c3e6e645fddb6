"""Hidden-effect test traces: one cause of design.md section 3 (or none) drawn at random.

:func:`draw_case` draws a cause and realistic cantilever / sample parameters from a seeded
generator; :func:`simulate_case` runs the simulator to steady state and writes a trace-format-v1
file whose ``/labels`` group holds the truth (``effect`` = the cause, ``model`` = every drawn
parameter). Diagnosis code never opens ``/labels``; tests, the benchmark and ``make demo``
compare its answer with the label afterwards.

Parameter ranges (SI), shared by every cause: TAP300AL-G-like lever (k = 20.68 N/m,
f0 = 259.9 kHz) with Q in [150, 450], rest gap 10 nm, free amplitude 1.2 - 1.8 x the gap, tip
radius 5 - 20 nm, Hamaker constant 0.5 - 2 x 1e-19 J, E* 1 - 5 GPa (polymers), a0 0.2 - 0.4 nm,
Gaussian noise (default 1 % of the free amplitude). Each effect has a strength range wide enough
to matter to the orbit and inside what the literature reports (see the ``_draw_*`` functions).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, final

import numpy as np

from afmlearn.io import Labels, Trace, write_trace
from simulator import (
    Cantilever,
    Scales,
    SensorChain,
    SteadyState,
    System,
    TipExcitation,
)
from simulator.forces import (
    DMT,
    Electrostatic,
    ExponentialDamping,
    ForceSum,
    HystereticJKR,
    NoInteraction,
    ViscoelasticDMT,
)
from simulator.integrate import RK4
from simulator.sensor import DetectorNonlinearity, GaussianNoise

__all__ = ["CAUSES", "EFFECT_CAUSES", "Case", "draw_case", "simulate_case", "hidden_trace"]

#: the cause vocabulary of design.md section 3 (``none`` first)
CAUSES: tuple[str, ...] = ("none", "higher_mode", "viscoelastic", "long_range_damping",
                           "contact_geometry", "adhesion_hysteresis", "electrostatic",
                           "detector_nonlinearity")
#: the causes that switch an effect on
EFFECT_CAUSES: tuple[str, ...] = CAUSES[1:]

_K = 20.68
_F0 = 259.9e3
_GAP = 10e-9


@final
@dataclass(frozen=True)
class Case:
    """One drawn hidden-effect case (SI parameters).

    Attributes
    ----------
    cause : str
        One of :data:`CAUSES`.
    quality_factor, free_amplitude_ratio, tip_radius_m, hamaker_j, reduced_modulus_pa, a0_m
        Lever and sample parameters shared by every cause.
    effect : dict
        The effect's own parameters (empty for ``none``).
    seed : int
        Seed of the sensor noise.
    """

    cause: str
    quality_factor: float
    free_amplitude_ratio: float
    tip_radius_m: float
    hamaker_j: float
    reduced_modulus_pa: float
    a0_m: float
    effect: dict[str, float] = field(default_factory=dict)
    seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {"cause": self.cause, "quality_factor": self.quality_factor,
                "free_amplitude_ratio": self.free_amplitude_ratio,
                "tip_radius_m": self.tip_radius_m, "hamaker_j": self.hamaker_j,
                "reduced_modulus_pa": self.reduced_modulus_pa, "a0_m": self.a0_m,
                "effect": dict(self.effect), "seed": self.seed}


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_case(rng: np.random.Generator, *, cause: str | None = None) -> Case:
    """Draw a case: the cause (uniform over :data:`CAUSES` unless given) and its parameters.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of every random choice (the cause included).
    cause : str, optional
        Force this cause (for per-cause benchmarks); the parameters stay random.
    """
    if cause is None:
        cause = str(rng.choice(CAUSES))
    if cause not in CAUSES:
        raise ValueError(f"cause must be one of {CAUSES}, got {cause!r}")
    q = float(rng.uniform(150.0, 450.0))
    ratio = float(rng.uniform(1.2, 1.8))
    radius = float(rng.uniform(5e-9, 20e-9))
    hamaker = float(rng.uniform(0.5e-19, 2e-19))
    e_star = _loguniform(rng, 1e9, 5e9)
    a0 = float(rng.uniform(0.2e-9, 0.4e-9))
    effect: dict[str, float] = {}
    if cause == "higher_mode":
        # second flexural mode near the 6:1 internal resonance (rectangular beam: 6.267)
        effect = {"frequency_ratio": float(rng.uniform(5.85, 6.3)),
                  "quality_factor_2": float(q * rng.uniform(1.5, 3.0))}
    elif cause == "viscoelastic":
        # eta sqrt(delta) delta' [N s / m^1.5]: 5-25 % of the drive energy into the sample
        effect = {"viscosity_si": _loguniform(rng, 0.03, 0.1)}
    elif cause == "long_range_damping":
        # squeeze-film / hydration-layer damping c exp(-z/z_b): c at z = 0 comparable to the
        # lever's own damping k/(Q omega0) ~ 3e-8 N s/m
        effect = {"coefficient_ns_per_m": _loguniform(rng, 1e-7, 3e-7),
                  "decay_length_m": float(rng.uniform(2e-9, 6e-9))}
    elif cause == "contact_geometry":
        # cone-like tip: F = kappa delta^p with p in [1.9, 2.4] (ch. 5 measured 2.27 +- 0.4);
        # kappa [N/m^p] gives the Sneddon cone force (2/pi) E* tan(theta) delta^2 (half angle
        # theta 20-35 deg) at delta = 1 nm
        theta = math.radians(float(rng.uniform(20.0, 35.0)))
        p = float(rng.uniform(1.9, 2.4))
        effect = {"exponent": p, "contact_coefficient":
                  2.0 / math.pi * e_star * math.tan(theta) * (1e-9) ** (2.0 - p)}
    elif cause == "adhesion_hysteresis":
        # JKR neck: work of adhesion of polymers against oxidised silicon
        effect = {"work_of_adhesion_j_per_m2": float(rng.uniform(0.1, 0.3))}
    elif cause == "electrostatic":
        # tip-sample potential difference (bias - contact potential), EFM/KPFM-like biases
        effect = {"voltage_v": float(rng.uniform(4.0, 8.0))}
    elif cause == "detector_nonlinearity":
        # optical-lever nonlinearity in free-amplitude units, both signs
        effect = {"a2": float(rng.choice([-1.0, 1.0]) * rng.uniform(0.02, 0.06)),
                  "a3": float(rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 0.02))}
    seed = int(rng.integers(2**31 - 1))
    return Case(cause=cause, quality_factor=q, free_amplitude_ratio=ratio, tip_radius_m=radius,
                hamaker_j=hamaker, reduced_modulus_pa=e_star, a0_m=a0, effect=effect,
                seed=seed)


def _force(case: Case, scales: Scales) -> Any:
    base = {"hamaker_j": case.hamaker_j, "tip_radius_m": case.tip_radius_m,
            "reduced_modulus_pa": case.reduced_modulus_pa, "a0_m": case.a0_m, "scales": scales}
    e = case.effect
    if case.cause == "viscoelastic":
        return ViscoelasticDMT.from_si(**base, viscosity_si=e["viscosity_si"])
    if case.cause == "contact_geometry":
        return DMT.from_si(**base, exponent=e["exponent"],
                           contact_coefficient=e["contact_coefficient"])
    if case.cause == "adhesion_hysteresis":
        return HystereticJKR.from_si(
            reduced_modulus_pa=case.reduced_modulus_pa, tip_radius_m=case.tip_radius_m,
            work_of_adhesion_j_per_m2=e["work_of_adhesion_j_per_m2"], a0_m=case.a0_m,
            scales=scales)
    dmt = DMT.from_si(**base)
    if case.cause == "long_range_damping":
        return ForceSum([dmt, ExponentialDamping.from_si(
            coefficient_ns_per_m=e["coefficient_ns_per_m"], decay_length_m=e["decay_length_m"],
            scales=scales)])
    if case.cause == "electrostatic":
        return ForceSum([dmt, Electrostatic.from_si(voltage_v=e["voltage_v"],
                                                    tip_radius_m=case.tip_radius_m,
                                                    scales=scales)])
    return dmt


def simulate_case(case: Case, path: str | os.PathLike[str], *, samples_per_period: int = 200,
                  n_periods: float = 300.0, noise_level: float = 0.01,
                  free_periods: float = 20.0, labels: bool = True,
                  require_tapping: bool = False) -> Path:
    """Simulate ``case`` in steady state and write it as a trace file (atomically).

    Parameters
    ----------
    case : Case
        From :func:`draw_case`.
    path : str or os.PathLike
        Output ``.h5`` file. Its name says nothing about the cause; keep it that way.
    samples_per_period : int
        Sampling rate / drive frequency, >= 20.
    n_periods : float
        Recorded drive periods (after settling for 3 Q periods), > 0.
    noise_level : float
        Gaussian noise std / free amplitude, in [0, 1].
    free_periods : float
        Length of the stored free (no-interaction) trace, same drive and sensor.
    labels : bool
        Write ``/labels`` (the truth).
    require_tapping : bool
        Raise ``_NotTapping`` (nothing written) when the steady orbit is not in the
        repulsive (tapping) regime.

    Returns
    -------
    pathlib.Path
    """
    if samples_per_period < 20:
        raise ValueError(f"samples_per_period must be >= 20, got {samples_per_period}")
    if not n_periods > 0:
        raise ValueError(f"n_periods must be > 0, got {n_periods}")
    scales = Scales(spring_constant=_K, resonance_frequency=_F0, length=_GAP)
    e = case.effect
    if case.cause == "higher_mode":
        cl = Cantilever.rectangular(n_modes=2, quality_factor=case.quality_factor,
                                    frequency_ratios=[1.0, e["frequency_ratio"]],
                                    higher_quality_factors=[e["quality_factor_2"]])
    else:
        cl = Cantilever.rectangular(n_modes=1, quality_factor=case.quality_factor)
    exc = TipExcitation.for_free_amplitude(cl, 1.0, case.free_amplitude_ratio)
    free_amp = exc.free_amplitude(cl, 1.0)
    stages: list[Any] = []
    if case.cause == "detector_nonlinearity":
        stages.append(DetectorNonlinearity(a2=e["a2"], a3=e["a3"]))
    stages.append(GaussianNoise(level=noise_level))
    sensor = SensorChain(stages, seed=case.seed)
    force = _force(case, scales)
    system = System(cl, force, exc)
    integrator = RK4(steps_per_period=120)
    sc = SteadyState(omega=1.0, gap=1.0, n_periods=n_periods,
                     settle_periods=3.0 * case.quality_factor,
                     samples_per_period=samples_per_period, integrator=integrator)
    res = sc.run(system)
    if require_tapping and res.labels["regime"] != "repulsive":
        raise _NotTapping(str(res.labels["regime"]))
    free_sc = SteadyState(omega=1.0, gap=1.0, n_periods=free_periods, settle_periods=0.0,
                          samples_per_period=samples_per_period, integrator=integrator)
    free = free_sc.run(System(cl, NoInteraction(), exc))
    si = res.to_si(scales)
    y = sensor(res.deflection, x_ref=free_amp, dt=res.dt) * scales.length
    y_free = sensor(free.deflection, x_ref=free_amp, dt=free.dt) * scales.length
    lab = None
    if labels:
        scalars = {k: (v if isinstance(v, str) else float(v)) for k, v in si["labels"].items()}
        lab = Labels(si["force_n"], modal_m=si["modal_m"],
                     model={"name": force.name, "case": case.to_dict(),
                            "force": force.to_dict()},
                     effect=case.cause, scalars=scalars,
                     extra={"tip_sample_gap_m": res.gap * scales.length})
    # no higher_mode_frequencies_hz: writing it only for two-mode cases would give the cause
    # away (the diagnosis searches the mode's frequency itself when the file does not give it)
    trace = Trace(y, sample_rate_hz=float(si["sample_rate_hz"]),
                  drive_frequency_hz=float(si["drive_frequency_hz"]), gap_m=si["gap_m"],
                  free_deflection_m=y_free, labels=lab,
                  spring_constant_n_per_m=_K, quality_factor=case.quality_factor,
                  resonance_frequency_hz=_F0, free_amplitude_m=free_amp * _GAP,
                  excitation="tip", tip_radius_m=case.tip_radius_m,
                  description="afmlearn steady tapping trace")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_trace(trace, path)
    return path


class _NotTapping(RuntimeError):
    """The drawn case settled on a non-tapping orbit (attractive regime or free)."""


def hidden_trace(rng: np.random.Generator, path: str | os.PathLike[str], *,
                 cause: str | None = None, max_draws: int = 50, **kwargs: Any) -> Case:
    """Draw a case (cause hidden unless given) and write its tapping-mode trace to ``path``.

    Draws again, with the same ``rng``, while the steady orbit is not in the repulsive
    (tapping) regime: at free amplitudes of 1.2 - 1.8 gaps some parameter sets settle on the
    attractive branch, where no contact effect can show. ``kwargs`` go to
    :func:`simulate_case`. Returns the case (the truth: keep it away from the code under test).
    """
    for _ in range(max_draws):
        case = draw_case(rng, cause=cause)
        try:
            simulate_case(case, path, require_tapping=True, **kwargs)
        except _NotTapping:
            continue
        return case
    raise RuntimeError(f"no tapping orbit in {max_draws} draws (cause {cause!r})")
