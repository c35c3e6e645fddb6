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
from numpy.typing import NDArray

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
from simulator.scenarios import Spectroscopy
from simulator.sensor import DetectorNonlinearity, GaussianNoise

__all__ = ["CAUSES", "EFFECT_CAUSES", "EFFECT_PAIRS", "Case", "SeriesCase", "draw_case",
           "simulate_case", "hidden_trace", "draw_series_case", "simulate_series",
           "hidden_series", "series_files", "effect_visibility"]

#: the cause vocabulary of design.md section 3 (``none`` first)
CAUSES: tuple[str, ...] = ("none", "higher_mode", "viscoelastic", "long_range_damping",
                           "contact_geometry", "adhesion_hysteresis", "electrostatic",
                           "detector_nonlinearity")
#: the causes that switch an effect on
EFFECT_CAUSES: tuple[str, ...] = CAUSES[1:]

FloatArray = NDArray[np.float64]

_K = 20.68
_F0 = 259.9e3
_GAP = 10e-9
#: largest |deflection| / free amplitude of a simulated row accepted as a recording
_MAX_REACH = 1.5


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
    effect = _draw_effect(rng, cause, quality_factor=q, reduced_modulus_pa=e_star)
    seed = int(rng.integers(2**31 - 1))
    return Case(cause=cause, quality_factor=q, free_amplitude_ratio=ratio, tip_radius_m=radius,
                hamaker_j=hamaker, reduced_modulus_pa=e_star, a0_m=a0, effect=effect,
                seed=seed)


def _draw_effect(rng: np.random.Generator, cause: str, *, quality_factor: float,
                 reduced_modulus_pa: float, series: bool = False) -> dict[str, float]:
    """The effect's own parameters (SI; empty for ``none``), drawn from ``rng``."""
    q, e_star = quality_factor, reduced_modulus_pa
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
        # tip-sample potential difference (bias - contact potential), EFM/KPFM-like biases;
        # set-point series 2 - 5 V: above ~5 V (pi eps0 R V^2 / z ~ 15 nN at 1 nm) most
        # set-points settle on the attractive branch (measured), which a tapping-mode user
        # avoids; one orbit 4 - 8 V (below ~4 V invisible on one orbit, docs/diagnose.md)
        lo, hi = (2.0, 5.0) if series else (4.0, 8.0)
        effect = {"voltage_v": float(rng.uniform(lo, hi))}
    elif cause == "detector_nonlinearity":
        # optical-lever nonlinearity in free-amplitude units, both signs
        effect = {"a2": float(rng.choice([-1.0, 1.0]) * rng.uniform(0.02, 0.06)),
                  "a3": float(rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 0.02))}
    return effect


def _force(case: Case, scales: Scales) -> Any:
    causes = () if case.cause == "none" else (case.cause,)
    return _tip_sample_force(causes, {case.cause: case.effect}, hamaker_j=case.hamaker_j,
                             tip_radius_m=case.tip_radius_m,
                             reduced_modulus_pa=case.reduced_modulus_pa, a0_m=case.a0_m,
                             scales=scales)


def _tip_sample_force(causes: tuple[str, ...], effects: dict[str, dict[str, float]], *,
                      hamaker_j: float, tip_radius_m: float, reduced_modulus_pa: float,
                      a0_m: float, scales: Scales) -> Any:
    """The simulator force model with the tip-sample effects of ``causes`` switched on.

    The contact law is DMT (a cone-like power law for ``contact_geometry``, plus the
    Kelvin--Voigt rate term for ``viscoelastic``) or the hysteretic JKR neck; long-range
    damping and electrostatics are added terms. ``higher_mode`` and ``detector_nonlinearity``
    act on the lever and the sensor, not here.
    """
    base = {"hamaker_j": hamaker_j, "tip_radius_m": tip_radius_m,
            "reduced_modulus_pa": reduced_modulus_pa, "a0_m": a0_m, "scales": scales}
    if "adhesion_hysteresis" in causes:
        e = effects["adhesion_hysteresis"]
        contact: Any = HystereticJKR.from_si(
            reduced_modulus_pa=reduced_modulus_pa, tip_radius_m=tip_radius_m,
            work_of_adhesion_j_per_m2=e["work_of_adhesion_j_per_m2"], a0_m=a0_m,
            scales=scales)
    else:
        law: dict[str, float] = {}
        if "contact_geometry" in causes:
            e = effects["contact_geometry"]
            law = {"exponent": e["exponent"], "contact_coefficient": e["contact_coefficient"]}
        contact = DMT.from_si(**base, **law)
        if "viscoelastic" in causes:
            visco = ViscoelasticDMT.from_si(**base,
                                            viscosity_si=effects["viscoelastic"]["viscosity_si"])
            contact = (visco if not law else
                       ViscoelasticDMT(**{**visco.parameters(), **contact.parameters()}))
    terms = [contact]
    if "long_range_damping" in causes:
        e = effects["long_range_damping"]
        terms.append(ExponentialDamping.from_si(
            coefficient_ns_per_m=e["coefficient_ns_per_m"], decay_length_m=e["decay_length_m"],
            scales=scales))
    if "electrostatic" in causes:
        terms.append(Electrostatic.from_si(voltage_v=effects["electrostatic"]["voltage_v"],
                                           tip_radius_m=tip_radius_m, scales=scales))
    return terms[0] if len(terms) == 1 else ForceSum(terms)


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


# ---------------------------------------------------------------------- set-point series
#: pairs of effects that the simulator can switch on together (the hysteretic JKR neck has
#: its own sphere law, so it combines with neither a cone-like exponent nor the
#: Kelvin--Voigt term)
EFFECT_PAIRS: tuple[tuple[str, str], ...] = tuple(
    (a, b) for i, a in enumerate(EFFECT_CAUSES) for b in EFFECT_CAUSES[i + 1:]
    if {a, b} not in ({"adhesion_hysteresis", "contact_geometry"},
                      {"adhesion_hysteresis", "viscoelastic"}))


@final
@dataclass(frozen=True)
class SeriesCase:
    """One drawn set-point series: the hidden effects and every parameter (SI).

    Attributes
    ----------
    causes : tuple of str
        The effects switched on (empty: ``none``; one or two of :data:`EFFECT_CAUSES`).
    quality_factor : float
        Q of the fundamental, 150 - 450.
    free_amplitude_m : float
        Free amplitude at the drive [m], 12 - 40 nm (the tapping range of a stiff lever).
    setpoints : tuple of float
        Rest gap / free amplitude of each row, decreasing (an approach), 0.3 - 0.92.
    settle_offsets : tuple of float
        Drive phase at each row's first sample / ``2 pi``, in [0, 1) (random per row).
    tip_radius_m, hamaker_j, reduced_modulus_pa, a0_m : float
        Sample and tip, as :class:`Case`.
    effects : dict of str to dict
        Per cause, the effect's own parameters.
    seed : int
        Seed of the sensor noise.
    free_amplitudes_m : tuple of float
        Free amplitude of each row [m] for an experiment at several free amplitudes (one
        file per free amplitude, :func:`simulate_series`); empty: every row at
        ``free_amplitude_m`` (then the first, smallest, free amplitude).
    """

    causes: tuple[str, ...]
    quality_factor: float
    free_amplitude_m: float
    setpoints: tuple[float, ...]
    settle_offsets: tuple[float, ...]
    tip_radius_m: float
    hamaker_j: float
    reduced_modulus_pa: float
    a0_m: float
    effects: dict[str, dict[str, float]] = field(default_factory=dict)
    seed: int = 0
    free_amplitudes_m: tuple[float, ...] = ()

    @property
    def cause(self) -> str:
        """The label: ``none``, the cause, or both causes joined by ``+``."""
        return "+".join(self.causes) if self.causes else "none"

    @property
    def row_amplitudes_m(self) -> FloatArray:
        """Free amplitude of each row [m], shape (n_points,)."""
        if self.free_amplitudes_m:
            return np.asarray(self.free_amplitudes_m, float)
        return np.full(len(self.setpoints), self.free_amplitude_m)

    @property
    def amplitudes_m(self) -> tuple[float, ...]:
        """The distinct free amplitudes [m], in row order (one file each)."""
        return tuple(dict.fromkeys(float(a) for a in self.row_amplitudes_m))

    @property
    def gaps_m(self) -> FloatArray:
        """Rest gap of each row [m], shape (n_points,)."""
        return np.asarray(self.setpoints) * self.row_amplitudes_m

    def one_amplitude(self) -> SeriesCase:
        """The same draw recorded at one free amplitude: every row at the first
        (``free_amplitude_m``), same set-points, drive phases, noise seeds, tip and law.

        Its rows at the first amplitude are the same records as this case's (for comparing
        a two-amplitude experiment with a one-amplitude one of as many set-points).
        """
        return SeriesCase(**{**self.__dict__, "free_amplitudes_m": ()})

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SeriesCase:
        """Inverse of :meth:`to_dict` (the ``cause`` label is derived, so ignored)."""
        return cls(causes=tuple(d["causes"]), quality_factor=float(d["quality_factor"]),
                   free_amplitude_m=float(d["free_amplitude_m"]),
                   setpoints=tuple(float(v) for v in d["setpoints"]),
                   settle_offsets=tuple(float(v) for v in d["settle_offsets"]),
                   tip_radius_m=float(d["tip_radius_m"]), hamaker_j=float(d["hamaker_j"]),
                   reduced_modulus_pa=float(d["reduced_modulus_pa"]), a0_m=float(d["a0_m"]),
                   effects={k: dict(v) for k, v in d["effects"].items()},
                   seed=int(d["seed"]),
                   free_amplitudes_m=tuple(float(v) for v in d.get("free_amplitudes_m", ())))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"cause": self.cause, "causes": list(self.causes),
                "quality_factor": self.quality_factor,
                "free_amplitude_m": self.free_amplitude_m, "setpoints": list(self.setpoints),
                "settle_offsets": list(self.settle_offsets), "tip_radius_m": self.tip_radius_m,
                "hamaker_j": self.hamaker_j, "reduced_modulus_pa": self.reduced_modulus_pa,
                "a0_m": self.a0_m, "effects": {k: dict(v) for k, v in self.effects.items()},
                "seed": self.seed}
        if self.free_amplitudes_m:
            out["free_amplitudes_m"] = list(self.free_amplitudes_m)
        return out


def _as_causes(causes: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    if isinstance(causes, str):
        causes = () if causes == "none" else tuple(causes.split("+"))
    out = tuple(causes)
    bad = [c for c in out if c not in EFFECT_CAUSES]
    if bad or len(set(out)) != len(out) or len(out) > 2:
        raise ValueError(f"causes must be 'none', one of {EFFECT_CAUSES} or two different "
                         f"ones joined by '+', got {causes!r}")
    if len(out) == 2 and tuple(sorted(out, key=EFFECT_CAUSES.index)) not in EFFECT_PAIRS:
        raise ValueError(f"causes {out} cannot be simulated together; pairs: {EFFECT_PAIRS}")
    return tuple(sorted(out, key=EFFECT_CAUSES.index))


def draw_series_case(rng: np.random.Generator, *,
                     causes: str | tuple[str, ...] | None = None, n_points: int = 8,
                     two_effect_share: float = 0.25, free_amplitudes: int = 1) -> SeriesCase:
    """Draw a set-point series: the hidden effects and every parameter.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of every random choice (the causes included).
    causes : str or tuple of str, optional
        Force these effects (``"none"``, a cause, ``"a+b"`` or a tuple); the parameters stay
        random. Default: with probability ``two_effect_share`` a pair of
        :data:`EFFECT_PAIRS`, otherwise one of :data:`CAUSES` (``none`` included), uniformly.
    n_points : int
        Set-points (rows), 1 - 64. They spread over the rest-gap / free-amplitude range a
        user scans in tapping mode: from 0.80 - 0.92 down to 0.30 - 0.45, evenly with a
        jitter of a quarter step.
    two_effect_share : float
        In [0, 1]; see ``causes``.
    free_amplitudes : {1, 2}
        1: one free amplitude, log-uniform in 12 - 40 nm (the draws of a seed are those of
        the one-amplitude generator). 2: an experiment at two free amplitudes of one tip,
        ``n_points / 2`` set-points each (``n_points`` even): the first log-uniform in
        12 nm - 40 nm / r, the second r times larger, r uniform in 2.5 - 3.3 (both in the
        tapping range). The ``n_points`` set-points are drawn as for one amplitude and dealt
        alternately (every other one, so each amplitude spans the range): the first
        amplitude's rows first, then the second's. A larger free amplitude indents further
        at the same set-point ratio, which is what bounds the contact law
        (docs/diagnose.md, "Several free amplitudes"); :meth:`SeriesCase.one_amplitude` is
        the same draw at the first amplitude only.
    """
    if not (isinstance(n_points, (int, np.integer)) and 1 <= n_points <= 64):
        raise ValueError(f"n_points must be an integer in [1, 64], got {n_points!r}")
    if free_amplitudes not in (1, 2) or isinstance(free_amplitudes, bool):
        raise ValueError(f"free_amplitudes must be 1 or 2, got {free_amplitudes!r}")
    if free_amplitudes == 2 and (n_points < 2 or n_points % 2):
        raise ValueError(f"n_points must be even and >= 2 for two free amplitudes, got "
                         f"{n_points!r}")
    if not 0.0 <= two_effect_share <= 1.0:
        raise ValueError(f"two_effect_share must be in [0, 1], got {two_effect_share!r}")
    if causes is None:
        if rng.uniform() < two_effect_share:
            chosen: tuple[str, ...] = EFFECT_PAIRS[int(rng.integers(len(EFFECT_PAIRS)))]
        else:
            c = str(rng.choice(CAUSES))
            chosen = () if c == "none" else (c,)
    else:
        chosen = _as_causes(causes)
    q = float(rng.uniform(150.0, 450.0))
    if free_amplitudes == 1:
        amp = _loguniform(rng, 12e-9, 40e-9)
    else:
        ratio = float(rng.uniform(2.5, 3.3))
        amp = _loguniform(rng, 12e-9, 40e-9 / ratio)
    hi, lo = float(rng.uniform(0.80, 0.92)), float(rng.uniform(0.30, 0.45))
    step = (hi - lo) / max(n_points - 1, 1)
    sp = np.linspace(hi, lo, n_points) + rng.uniform(-0.25, 0.25, n_points) * step
    if n_points == 1:
        sp = np.array([float(rng.uniform(lo, hi))])
    offsets = rng.uniform(0.0, 1.0, n_points)
    radius = float(rng.uniform(5e-9, 20e-9))
    hamaker = float(rng.uniform(0.5e-19, 2e-19))
    e_star = _loguniform(rng, 1e9, 5e9)
    a0 = float(rng.uniform(0.2e-9, 0.4e-9))
    effects = {c: _draw_effect(rng, c, quality_factor=q, reduced_modulus_pa=e_star,
                               series=True) for c in chosen}
    seed = int(rng.integers(2**31 - 1))
    amps: tuple[float, ...] = ()
    if free_amplitudes == 2:
        order = np.r_[np.arange(0, n_points, 2), np.arange(1, n_points, 2)]
        sp = sp[order]
        amps = tuple(amp * (1.0 if k % 2 == 0 else ratio) for k in order)
    return SeriesCase(causes=chosen, quality_factor=q, free_amplitude_m=amp,
                      setpoints=tuple(float(v) for v in sp),
                      settle_offsets=tuple(float(v) for v in offsets), tip_radius_m=radius,
                      hamaker_j=hamaker, reduced_modulus_pa=e_star, a0_m=a0, effects=effects,
                      seed=seed, free_amplitudes_m=amps)


def simulate_series(case: SeriesCase, path: str | os.PathLike[str], *,
                    samples_per_period: int = 200, n_periods: float = 40.0,
                    noise_level: float = 0.01, free_periods: float = 20.0,
                    drive_phase: bool = True, labels: bool = True,
                    min_tapping: int = 0) -> Path:
    """Simulate the set-point series of ``case`` and write it as one trace file (atomically),
    or, for a case at several free amplitudes, one file per free amplitude in a folder.

    The rows come from the simulator's ``spectroscopy`` scenario: each a steady record at its
    rest gap, reached as an approach reaches it (started on the free orbit, the rest gap
    stepped to the row's, settled for ``3 Q`` periods), recorded for ``n_periods`` from a
    random drive phase per row. Where both branches are stable the start decides between
    the attractive and the tapping one, as in an instrument; rows of both kinds can occur.
    The file holds ``deflection_m`` (n_points, n), ``gap_m`` (n_points,), the free trace and,
    with ``drive_phase``, ``drive_phase_rad`` (n_points,) (the drive phase at each row's first
    sample: drive ``cos(2 pi f_d t + drive_phase_rad)``, towards the sample). The truth goes
    only into ``/labels`` (force, modal deflections, per-row scalars, ``effect`` = the causes
    joined by ``+``); no attribute says which effect is on.

    Several free amplitudes (``case.free_amplitudes_m``): ``path`` is a folder, which gets
    one such file per free amplitude, ``amplitude-0.h5`` (the first, smallest), then
    ``amplitude-1.h5``, each a valid trace-format-v1 series with its own free trace,
    ``free_amplitude_m`` and rows (same lever, tip and law; ``/labels`` of each file: its
    rows, and the whole case). :func:`series_files` lists them; diagnose them as one
    experiment with ``afmlearn.diagnose.observation.read_experiment(series_files(path))``
    or ``scripts/diagnose.py trace=[.../amplitude-0.h5,.../amplitude-1.h5]``.

    Parameters
    ----------
    case : SeriesCase
        From :func:`draw_series_case`.
    path : str or os.PathLike
        Output ``.h5`` file (a folder for several free amplitudes); its name says nothing
        about the cause.
    samples_per_period : int
        Sampling rate / drive frequency, >= 20.
    n_periods : float
        Recorded drive periods per row, >= 5.
    noise_level : float
        Gaussian noise std / free amplitude, in [0, 1] (independent per row).
    free_periods : float
        Length of the stored free trace (same drive and sensor), > 0.
    drive_phase : bool
        Write ``drive_phase_rad`` (an instrument that captures the drive reference);
        False: not recorded.
    labels : bool
        Write ``/labels``.
    min_tapping : int
        Raise ``_NotTapping`` (nothing written) when fewer rows than this are in the
        repulsive (tapping) regime (per free amplitude, whose deepest row must tap).

    Returns
    -------
    pathlib.Path
        The file (the folder for several free amplitudes).

    Raises
    ------
    FloatingPointError
        When a row's integration diverged: non-finite, or ``|deflection|`` above 1.5 free
        amplitudes (nothing written; :func:`hidden_series` draws again).
    """
    groups = _simulate_groups(case, samples_per_period=samples_per_period,
                              n_periods=n_periods, noise_level=noise_level,
                              free_periods=free_periods, min_tapping=min_tapping)
    if len(groups) == 1:
        return _write_series(groups[0], path, drive_phase=drive_phase, labels=labels)
    folder = Path(path)
    for g, data in enumerate(groups):
        _write_series(data, folder / f"amplitude-{g}.h5", drive_phase=drive_phase,
                      labels=labels)
    return folder


def series_files(path: str | os.PathLike[str]) -> list[Path]:
    """The trace files :func:`simulate_series` wrote at ``path``: the file itself, or a
    folder's ``amplitude-*.h5`` in order (first free amplitude first)."""
    path = Path(path)
    if path.is_dir():
        files = sorted(path.glob("amplitude-*.h5"), key=lambda p: int(p.stem.split("-")[1]))
        if not files:
            raise ValueError(f"path: no amplitude-*.h5 in the folder {path}")
        return files
    return [path]


@final
@dataclass(frozen=True)
class _SeriesData:
    """Simulated rows of a series in SI before writing (see :func:`simulate_series`)."""

    case: SeriesCase
    rows: tuple[int, ...]             # the case's rows simulated here (one free amplitude)
    free_amplitude_m: float
    deflection_m: FloatArray          # (n_points, n)
    force_n: FloatArray               # (n_points, n)
    modal_m: FloatArray               # (n_modes, n_points, n)
    tip_sample_gap_m: FloatArray      # (n_points, n)
    drive_phase_rad: FloatArray       # (n_points,)
    scalars: dict[str, Any]
    free_deflection_m: FloatArray     # (m,)
    sample_rate_hz: float
    drive_frequency_hz: float
    force_model: dict[str, Any]


def _simulate_series(case: SeriesCase, *, samples_per_period: int, n_periods: float,
                     noise_level: float, free_periods: float, min_tapping: int) -> _SeriesData:
    """The rows of a one-amplitude ``case`` (:func:`_simulate_groups` for several)."""
    groups = _simulate_groups(case, samples_per_period=samples_per_period,
                              n_periods=n_periods, noise_level=noise_level,
                              free_periods=free_periods, min_tapping=min_tapping)
    if len(groups) != 1:
        raise ValueError(f"case has {len(groups)} free amplitudes; simulate them by group")
    return groups[0]


def _simulate_groups(case: SeriesCase, *, samples_per_period: int, n_periods: float,
                     noise_level: float, free_periods: float, min_tapping: int
                     ) -> list[_SeriesData]:
    """The rows of ``case``, one :class:`_SeriesData` per free amplitude (in row order).

    Row ``i``'s sensor noise is seeded by ``(seed, i + 1)`` whatever its amplitude, and the
    first amplitude's free trace by ``(seed, 0)``, so the rows at the first amplitude are
    those of :meth:`SeriesCase.one_amplitude`. ``min_tapping`` applies to each amplitude
    (and its deepest row must tap).
    """
    amps = case.row_amplitudes_m
    out = []
    for g, a in enumerate(case.amplitudes_m):
        rows = tuple(int(i) for i in np.flatnonzero(amps == a))
        out.append(_simulate_rows(case, rows, a, 0 if g == 0 else len(amps) + g,
                                  samples_per_period=samples_per_period, n_periods=n_periods,
                                  noise_level=noise_level, free_periods=free_periods,
                                  min_tapping=min_tapping))
    return out


def _simulate_rows(case: SeriesCase, rows: tuple[int, ...], free_amplitude_m: float,
                   free_seed: int, *, samples_per_period: int, n_periods: float,
                   noise_level: float, free_periods: float, min_tapping: int) -> _SeriesData:
    if samples_per_period < 20:
        raise ValueError(f"samples_per_period must be >= 20, got {samples_per_period}")
    if not n_periods >= 5:
        raise ValueError(f"n_periods must be >= 5, got {n_periods}")
    if not 0.0 <= noise_level <= 1.0:
        raise ValueError(f"noise_level must be in [0, 1], got {noise_level}")
    if not free_periods > 0:
        raise ValueError(f"free_periods must be > 0, got {free_periods}")
    scales = Scales(spring_constant=_K, resonance_frequency=_F0, length=_GAP)
    if "higher_mode" in case.causes:
        e = case.effects["higher_mode"]
        cl = Cantilever.rectangular(n_modes=2, quality_factor=case.quality_factor,
                                    frequency_ratios=[1.0, e["frequency_ratio"]],
                                    higher_quality_factors=[e["quality_factor_2"]])
    else:
        cl = Cantilever.rectangular(n_modes=1, quality_factor=case.quality_factor)
    amp = free_amplitude_m / _GAP
    exc = TipExcitation.for_free_amplitude(cl, 1.0, amp)
    free_amp = exc.free_amplitude(cl, 1.0)

    def sensor(i: int) -> SensorChain:
        stages: list[Any] = []
        if "detector_nonlinearity" in case.causes:
            d = case.effects["detector_nonlinearity"]
            stages.append(DetectorNonlinearity(a2=d["a2"], a3=d["a3"]))
        stages.append(GaussianNoise(level=noise_level))
        return SensorChain(stages, seed=int(np.random.SeedSequence([case.seed, i])
                                            .generate_state(1)[0]))

    force = _tip_sample_force(case.causes, case.effects, hamaker_j=case.hamaker_j,
                              tip_radius_m=case.tip_radius_m,
                              reduced_modulus_pa=case.reduced_modulus_pa, a0_m=case.a0_m,
                              scales=scales)
    system = System(cl, force, exc)
    integrator = RK4(steps_per_period=120)
    idx = np.asarray(rows, int)
    gaps = np.asarray(case.setpoints)[idx] * amp
    res = Spectroscopy(omega=1.0, gaps=gaps, n_periods=n_periods,
                       drive_phases=2 * np.pi * np.asarray(case.settle_offsets)[idx],
                       settle_periods=3.0 * case.quality_factor,
                       samples_per_period=samples_per_period, integrator=integrator).run(system)
    # a steady tapping or attractive orbit stays within ~the free amplitude; rows far beyond
    # it are integration failures that came out finite (measured: 7x - 6e11x on 12 of 70
    # drawn series at 200 samples/period), not recordings
    reach = np.max(np.abs(np.asarray(res.deflection)), axis=-1) / free_amp
    if not np.all(np.isfinite(reach)) or np.any(reach > _MAX_REACH):
        bad = np.flatnonzero(~(reach <= _MAX_REACH))
        raise FloatingPointError(f"rows {idx[bad].tolist()} diverged: |deflection| up to "
                                 f"{float(np.nanmax(reach)):.3g} free amplitudes")
    si = res.to_si(scales)
    lab = si["labels"]
    tapping = int(sum(r == "repulsive" for r in lab["regime"]))
    deepest = int(np.argmin(gaps))
    if tapping < min_tapping or (min_tapping > 0 and lab["regime"][deepest] != "repulsive"):
        raise _NotTapping(f"{tapping} of {gaps.size} rows tapping, need {min_tapping}")
    phase = np.mod(np.broadcast_to(si["drive_phase_rad"], gaps.shape), 2 * np.pi)
    done = [{"y": res.deflection[k], "force": si["force_n"][k], "modal": si["modal_m"][:, k],
             "z": res.gap[k] * _GAP, "phase": float(phase[k]), "dt": res.dt,
             "labels": {key: v[k] for key, v in lab.items()}} for k in range(gaps.size)]
    ys = [sensor(rows[k] + 1)(r["y"], x_ref=free_amp, dt=r["dt"]) * _GAP
          for k, r in enumerate(done)]
    free_sc = SteadyState(omega=1.0, gap=1.0, n_periods=free_periods, settle_periods=0.0,
                          samples_per_period=samples_per_period, integrator=integrator)
    free = free_sc.run(System(cl, NoInteraction(), exc))
    y_free = sensor(free_seed)(free.deflection, x_ref=free_amp, dt=free.dt) * _GAP
    scalars: dict[str, Any] = {}
    for key in done[0]["labels"]:
        vals = [r["labels"][key] for r in done]
        if all(isinstance(u, str) for u in vals):
            scalars[key] = vals[0] if len(set(vals)) == 1 else ",".join(vals)
        else:
            scalars[key] = np.asarray(vals, float)
    return _SeriesData(case=case, rows=tuple(rows), free_amplitude_m=free_amplitude_m,
                       deflection_m=np.asarray(ys),
                       force_n=np.asarray([r["force"] for r in done]),
                       modal_m=np.stack([r["modal"] for r in done], axis=1),
                       tip_sample_gap_m=np.asarray([r["z"] for r in done]),
                       drive_phase_rad=np.asarray([r["phase"] for r in done]), scalars=scalars,
                       free_deflection_m=y_free, sample_rate_hz=float(si["sample_rate_hz"]),
                       drive_frequency_hz=float(np.atleast_1d(si["drive_frequency_hz"])[0]),
                       force_model={"name": force.name, "force": force.to_dict()})


def _write_series(data: _SeriesData, path: str | os.PathLike[str], *, drive_phase: bool,
                  labels: bool) -> Path:
    case = data.case
    lab = None
    if labels:
        lab = Labels(data.force_n, modal_m=data.modal_m,
                     model={**data.force_model, "case": case.to_dict()}, effect=case.cause,
                     scalars=data.scalars, extra={"tip_sample_gap_m": data.tip_sample_gap_m,
                                                  "drive_phase_rad": data.drive_phase_rad})
    # no higher_mode_frequencies_hz (it would give the cause away), neutral description
    trace = Trace(data.deflection_m, sample_rate_hz=data.sample_rate_hz,
                  drive_frequency_hz=data.drive_frequency_hz,
                  gap_m=case.gaps_m[np.asarray(data.rows, int)],
                  drive_phase_rad=data.drive_phase_rad if drive_phase else None,
                  free_deflection_m=data.free_deflection_m, labels=lab,
                  spring_constant_n_per_m=_K, quality_factor=case.quality_factor,
                  resonance_frequency_hz=_F0, free_amplitude_m=data.free_amplitude_m,
                  excitation="tip", tip_radius_m=case.tip_radius_m,
                  description="afmlearn set-point series")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_trace(trace, path)
    return path


def hidden_series(rng: np.random.Generator, path: str | os.PathLike[str], *,
                  causes: str | tuple[str, ...] | None = None, n_points: int = 8,
                  free_amplitudes: int = 1, max_draws: int = 50,
                  **kwargs: Any) -> SeriesCase:
    """Draw a series (effects hidden unless given) and write it to ``path`` (a folder of one
    file per free amplitude when ``free_amplitudes`` is 2; :func:`series_files`).

    Draws again, with the same ``rng``, while fewer than half of the rows (and the row at
    the smallest gap) tap, at each free amplitude: a user scanning set-points in tapping
    mode works where the tip touches, though strong attraction (a biased tip, a sticky
    sample) keeps the larger set-points on the attractive branch. ``kwargs`` go to
    :func:`simulate_series`. Returns the case (the truth: keep it away from the code under
    test).
    """
    per = max(n_points // max(int(free_amplitudes), 1), 1)
    for _ in range(max_draws):
        case = draw_series_case(rng, causes=causes, n_points=n_points,
                                free_amplitudes=free_amplitudes)
        try:
            simulate_series(case, path, min_tapping=max((per + 1) // 2, 1), **kwargs)
        except (_NotTapping, FloatingPointError):
            # FloatingPointError: the integration diverged (the tip crossed z = 0 where the
            # drawn law has no repulsion): no recording, draw again
            continue
        return case
    raise RuntimeError(f"no tapping series in {max_draws} draws (causes {causes!r})")


def effect_visibility(case: SeriesCase, *, samples_per_period: int = 200,
                      n_periods: float = 40.0, noise_level: float = 0.01,
                      n_harmonics: int = 30) -> dict[str, dict[str, Any]]:
    """How far each hidden effect moves the recorded orbits, in noise units (an oracle).

    For every cause of ``case`` the series is simulated without noise twice: as drawn, and
    as its *twin* with that one effect switched off (same lever, sample, set-points, drive
    phases). Per row, the period-averaged harmonics 0 - ``n_harmonics`` of the two records
    are compared in units of their standard error under the recording's white noise
    (``noise_level`` x free amplitude per sample): ``chi2 = sum_k |c_k - c_k'|^2 / (2
    sigma^2 / n)`` (``sigma^2 / n`` for the mean), ``n`` samples per row.

    This is the chi-square drop that the *true* law would give over the twin's law at the
    drawn parameters. The effect-free model refits its parameters, so a diagnosis can only
    see less: a draw whose ``chi2_total`` is below a cause's threshold is invisible, a larger
    value is necessary for a finding, not sufficient. For the benchmark and tests only: it
    reads the truth, so it is never passed to the code under test.

    Parameters
    ----------
    case : SeriesCase
        The drawn truth.
    samples_per_period, n_periods, noise_level
        As the recording (see :func:`simulate_series`).
    n_harmonics : int
        Highest harmonic compared, >= 1 (below the Nyquist limit).

    Returns
    -------
    dict
        Per cause: ``chi2_rows`` (list, per row), ``chi2_total`` (float), ``same_branch``
        (bool: every row in the same regime with and without the effect).
    """
    if not 1 <= n_harmonics < samples_per_period // 2:
        raise ValueError(f"n_harmonics must be in [1, samples_per_period // 2), got "
                         f"{n_harmonics}")
    if not 0.0 < noise_level <= 1.0:
        raise ValueError(f"noise_level must be in (0, 1], got {noise_level}")
    opts = {"samples_per_period": samples_per_period, "n_periods": n_periods,
            "noise_level": 0.0, "free_periods": 1.0, "min_tapping": 0}
    c_drawn, regime = _clean_rows(case, opts, samples_per_period, n_harmonics)
    n = int(n_periods) * samples_per_period
    sigma = noise_level * case.row_amplitudes_m[:, None]      # each row's own free amplitude
    weight = np.broadcast_to(n / (2 * sigma**2), (sigma.size, n_harmonics + 1)).copy()
    weight[:, 0] *= 2.0
    out: dict[str, dict[str, Any]] = {}
    for cause in case.causes:
        rest = tuple(c for c in case.causes if c != cause)
        c_twin, regime_twin = _clean_rows(
            SeriesCase(**{**case.__dict__, "causes": rest,
                          "effects": {c: case.effects[c] for c in rest}}),
            opts, samples_per_period, n_harmonics)
        rows = (np.abs(c_drawn - c_twin) ** 2 * weight).sum(axis=1)
        out[cause] = {"chi2_rows": [float(v) for v in rows], "chi2_total": float(rows.sum()),
                      "same_branch": regime == regime_twin}
    return out


def _clean_rows(case: SeriesCase, opts: dict[str, Any], spp: int, n_harmonics: int
                ) -> tuple[NDArray[np.complex128], list[str]]:
    """Harmonics (:func:`_row_harmonics`, rows in the case's order) and regime of every
    row of ``case`` simulated with ``opts`` (every free amplitude)."""
    groups = _simulate_groups(case, **opts)
    n_rows = len(case.setpoints)
    c = np.empty((n_rows, n_harmonics + 1), complex)
    regime = [""] * n_rows
    for data in groups:
        idx = np.asarray(data.rows, int)
        c[idx] = _row_harmonics(data.deflection_m, spp, n_harmonics)
        joined = str(data.scalars["regime"])      # one word when every row agrees
        words = joined.split(",") if "," in joined else [joined] * idx.size
        for k, r in zip(idx, words, strict=True):
            regime[int(k)] = r
    return c, regime


def _row_harmonics(y: FloatArray, spp: int, n_harmonics: int) -> NDArray[np.complex128]:
    """Complex harmonics 0 - n_harmonics of each row's period average, ``(n_rows, K + 1)``
    (``y = sum_k Re(c_k exp(i k phi))``; rows of whole periods, the remainder dropped)."""
    m = y.shape[1] // spp
    avg = y[:, : m * spp].reshape(y.shape[0], m, spp).mean(axis=1)
    c = np.fft.rfft(avg, axis=1)[:, : n_harmonics + 1] / spp
    c[:, 1:] *= 2.0
    return c
