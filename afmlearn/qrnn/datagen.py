"""Labelled frequency-sweep windows for the QRNN, drawn from the simulator and cached in HDF5.

What is generated
-----------------
``spec.n_cantilevers`` cantilevers, each swept ``spec.sweeps_per_cantilever`` times over
``Omega = omega_start ... omega_stop`` (``simulator.Sweep``, direction ``both``: a forward and a
reverse sweep run as one batch, each point continuing from the previous state; every point
integrates ``settle_periods`` periods unrecorded, then records ``record_periods`` periods of the
free resonance). Two families of cantilevers:

* ``sweet_spot`` (a share ``sweet_spot_fraction``): the 2-mode fit of chapter 3, Table 3.B.1
  (``conf/cantilever/sweet_spot.yaml``, ``conf/experiment/sweet_spot.yaml``: base excitation,
  piecewise modal damping, VdW--DMT with ``a0 = 0.2``, ``C1 = 6e-4``, ``G = 10.5``, mode-2 gain
  13.5/10.5) with ``K2 = 36 (1 +- 3 %)`` and the damping, ``C1`` and the dither amplitude
  jittered by a few tens of per cent;
* ``rectangular``: ``simulator.Cantilever.rectangular`` with 1, 2 or 3 modes (cycled through
  ``spec.modes``), ``Q1`` log-uniform in ``q_range``, mode-2 ratio near 6:1 (``K2 = 36 (1 +- 3
  %)``, share ``near_six_fraction``) or away from it (one of ``away_ratios``, e.g. 5.3, the
  beam's 6.267, 6.8), mode 3 at ``17.55 (1 +- 2 %)``, higher-mode Q log-uniform in
  ``higher_q_range``; tip or base excitation; DMT contact stiffness and ``C1`` drawn; the free
  amplitude at ``Omega = 1`` in ``free_amplitude_range`` (units of the rest gap).

Each sweep gets its own drive amplitude (free-amplitude ratio) and noise level (one of
``noise_levels``, ``simulator.sensor.GaussianNoise`` relative to the free amplitude).

Labels (per sweep point, exact: computed from the modal deflections ``q``)
------------------------------------------------------------------------
``coupling``
    ``simulator.labels.coupling_strength(q)``: share of the tip motion's variance carried by
    modes >= 2, ``var(sum_{i>=2} q_i) / (var(q_1) + var(sum_{i>=2} q_i))``, over the recorded
    span of the point (1-mode cantilevers: 0).
``coupled``
    ``coupling > coupling_threshold`` (default 0.003: the higher modes carry more than 5.5 %
    of the RMS tip motion). Reason: away from an internal resonance (mode-2 ratio 5.3, 6.267 or
    6.8) the higher modes only follow the impacts quasi-statically and their share stays below
    ~1e-3 even while tapping (measured on these sweeps); near 6:1 the 6th harmonic of the
    impacts drives mode 2 resonantly and the share rises to 0.003 ... 0.05 on the tapping
    branch. The threshold sits above the non-resonant ceiling with a factor ~4 of margin.
``sweet``
    Membership of the sweep's sweet-spot interval: the longest run (in sweep order) of
    *candidate* points -- coupled **and** tapping (``contact_fraction > 0``: the sweet spot is
    an intermittent-contact phenomenon; this excludes the free ring-down of mode 2 after the
    cantilever has dropped off the tapping branch) -- where gaps of at most ``sweet_max_gap``
    non-candidate points are bridged; runs with fewer than ``sweet_min_points`` candidates do not
    count. The interval is ``[min Omega, max Omega]`` over the run (:func:`sweet_interval`);
    every point inside it (bridged gaps included) has ``sweet = 1``; a sweep without such a run
    has no sweet spot (interval NaN).
``shares``
    ``var(q_i) / sum_j var(q_j)`` per mode, shape (3,) (zeros for absent modes), for the
    interpretation of hidden units.
also ``contact_fraction``, ``min_gap``, ``amplitude``, ``harmonic6`` (``|X_6| / |X_1|`` of the
tip deflection by lock-in over whole drive periods, the 6th-harmonic amplification).

Window representation (shared with :func:`afmlearn.qrnn.data.windows_from_trace`)
---------------------------------------------------------------------------------
A window starts at an arbitrary time (simulated windows: a random sample position, since a
recording's drive phase is unknown), is resampled by cubic interpolation to
``samples_per_period`` samples per **drive** period (``f_s / f_drive`` raw samples per period),
and spans one input period plus ``target_periods`` target periods. It is normalised with the
input period only -- ``u = (x - m) / s``, ``m`` the mean and ``s = sqrt(2) * std`` of the
input period (a sinusoid of amplitude A gives ``s = A``) -- so recorded traces need no labels
and no free amplitude, and any detector offset drops out. Network inputs ``x``, shape
``(P, 3)`` per window (:func:`input_features`): channel 0 the normalised input period ``u``,
channel 1 the detuning ``10 (Omega - 1)`` with ``Omega = f_drive / f0``, channel 2 the scale
``s`` in units of the rest gap (``s / gap_m`` for a recording). Targets ``y``: the
following periods of ``u``, shape (target_periods * P,). Nothing else (no drive phase, no modal
deflections) reaches the network.

Cache
-----
:func:`generate_dataset` writes one HDF5 file atomically (temporary sibling, then
``os.replace``); finished cantilevers are kept as shards in ``<file>.parts/`` so an interrupted
run resumes where it stopped. The SHA-256 of the spec (and of :data:`GENERATOR_VERSION`) is
stored as the attribute ``spec_hash``; a file with the same hash is reused as it is.

HDF5 layout: root attributes (``format``, ``spec_json``, ``spec_hash``, counts, timing);
``windows/{u, omega, scale, offset, point}`` (``u``: (W, (1 + target_periods) P) float32,
``point``: row in ``points``) plus copies of the point labels per window
(``cantilever_id, sweep_id, point_index, coupling, coupled, sweet, shares``);
``points/{omega, cantilever_id, sweep_id, point_index, coupling, coupled, sweet, shares,
contact_fraction, min_gap, amplitude, harmonic6}`` (N,); ``sweeps/{cantilever_id, n_modes,
family, direction, free_amplitude, noise_level, sweet_lo, sweet_hi}`` (S,);
``cantilevers/{n_modes, family, ratio2}`` (C,) and the attribute ``params_json``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import shutil
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

import h5py
import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from afmlearn.io._atomic import atomic_path
from simulator import RK4, BaseExcitation, Cantilever, SensorChain, Sweep, System, TipExcitation
from simulator.forces import DMT
from simulator.labels import coupling_strength, lock_in
from simulator.scenarios.spectroscopy import Spectroscopy
from simulator.sensor import GaussianNoise, LowPass, Quantizer

__all__ = [
    "DatasetSpec",
    "GENERATOR_VERSION",
    "FAMILIES",
    "DIRECTIONS",
    "EXCITATIONS",
    "N_FEATURES",
    "generate_dataset",
    "input_features",
    "normalise_windows",
    "resample_windows",
    "sweet_interval",
    "dataset_summary",
]

log = logging.getLogger(__name__)

#: bump when the generator's output changes for the same spec (part of the cache hash)
GENERATOR_VERSION = 2
#: family codes stored in ``cantilevers/family`` and ``sweeps/family``
FAMILIES: tuple[str, ...] = ("sweet_spot", "rectangular", "nonuniform")
#: excitation codes stored in ``cantilevers/excitation`` and ``sweeps/excitation``
EXCITATIONS: tuple[str, ...] = ("base", "tip")
#: record codes stored in ``sweeps/direction``: a sweep direction, or a set-point series
DIRECTIONS: tuple[str, ...] = ("forward", "reverse", "series")
#: number of input channels per time step (normalised deflection, detuning, scale)
N_FEATURES = 3
#: scale factor of the detuning channel ``DETUNING_GAIN * (Omega - 1)``
DETUNING_GAIN = 10.0
_FORMAT = "afmlearn-qrnn-dataset"

# Table 3.B.1 (physics.md section 2; conf/cantilever/sweet_spot.yaml)
_TABLE_DAMPING = (2.9e-3, 5.0e-4)
_TABLE_CONTACT_DAMPING = (5.7e-3, 8.0e-3)
_TABLE_BASE = (1.565980, -0.867872)
_TABLE_GAIN = 13.5 / 10.5
_TABLE_DITHER = 2.649109e-3


@final
@dataclass(frozen=True)
class DatasetSpec:
    """What to simulate (all dimensionless; frequencies in units of ``f0``).

    Parameters
    ----------
    n_cantilevers : int
        Number of cantilevers (>= 3, so that a split by cantilever is possible).
    sweeps_per_cantilever : int
        Sweeps (each forward + reverse) per cantilever, each with its own drive amplitude and
        noise level (>= 1).
    modes : sequence of int
        Mode counts cycled through by the ``rectangular`` family (values in {1, 2, 3}).
    sweet_spot_fraction : float
        Share of cantilevers from the Table 3.B.1 family, in [0, 1].
    near_six_fraction : float
        Share of multi-mode rectangular cantilevers with ``K2 = 36 (1 +- 3 %)``, in [0, 1].
    away_ratios : sequence of float
        Mode-2 frequency ratios used away from 6:1 (each > 1).
    q_range, higher_q_range : (float, float)
        Log-uniform ranges of ``Q1`` and of the higher modes' Q (rectangular family).
    free_amplitude_range : (float, float)
        Free amplitude at ``Omega = 1`` over the rest gap (rectangular family; the sweet-spot
        family jitters the dither amplitude by +- 10 % instead).
    omega_start, omega_stop : float
        Sweep range (0 < start < stop).
    n_points : int
        Points per sweep direction (>= 4).
    settle_periods : float
        Free-resonance periods integrated before each recorded point (>= 0).
    record_periods : int
        Free-resonance periods recorded per point (>= target_periods + 2).
    initial_settle_periods : float
        Settling at the first point (>= 0).
    sim_samples_per_period : int
        Simulator output samples per free-resonance period (>= 40).
    steps_per_period : int
        RK4 resolution target (steps per period of the fastest motion, >= 30).
    samples_per_period : int
        Samples per drive period after resampling, ``P`` (>= 16).
    target_periods : int
        Target periods stored after the input period (>= 1).
    windows_per_point : int
        Windows cut from each recorded point (>= 1).
    noise_levels : sequence of float
        Gaussian noise levels relative to the free amplitude, drawn per sweep (each in [0, 1]).
    coupling_threshold : float
        ``coupled = coupling > coupling_threshold``, in (0, 1).
    sweet_max_gap, sweet_min_points : int
        Sweet-spot run definition (see the module docstring).
    seed : int
        Seed of every random draw.
    """

    n_cantilevers: int = 40
    sweeps_per_cantilever: int = 2
    modes: tuple[int, ...] = (1, 2, 3)
    sweet_spot_fraction: float = 0.3
    near_six_fraction: float = 0.6
    away_ratios: tuple[float, ...] = (5.3, 6.267, 6.8)
    q_range: tuple[float, float] = (150.0, 500.0)
    higher_q_range: tuple[float, float] = (1000.0, 12000.0)
    free_amplitude_range: tuple[float, float] = (0.95, 1.35)
    omega_start: float = 0.985
    omega_stop: float = 1.03
    n_points: int = 60
    settle_periods: float = 20.0
    record_periods: int = 9
    initial_settle_periods: float = 200.0
    sim_samples_per_period: int = 128
    steps_per_period: int = 60
    samples_per_period: int = 64
    target_periods: int = 6
    windows_per_point: int = 2
    noise_levels: tuple[float, ...] = (0.0, 0.005, 0.01, 0.02)
    coupling_threshold: float = 0.003
    sweet_max_gap: int = 2
    sweet_min_points: int = 2
    seed: int = 0
    nonuniform_fraction: float = 0.0
    tip_fraction: float = 0.5
    sweet_spot_tip_fraction: float = 0.0
    exact_six_fraction: float = 0.0
    ratio2_range: tuple[float, ...] = ()
    series_per_cantilever: int = 0
    n_setpoints: int = 6
    setpoint_range: tuple[float, float] = (0.3, 0.95)
    series_free_amplitude_range: tuple[float, float] = (0.6, 2.0)
    series_omega_range: tuple[float, float] = (0.99, 1.01)
    series_periods: int = 10
    series_settle_q: float = 1.5
    sim_samples_choices: tuple[int, ...] = ()
    lowpass_range: tuple[float, ...] = ()
    adc_bits: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        ints = {"n_cantilevers": 3, "sweeps_per_cantilever": 0, "n_points": 4,
                "series_per_cantilever": 0, "n_setpoints": 1, "series_periods": 3,
                "sim_samples_per_period": 40, "steps_per_period": 30, "samples_per_period": 16,
                "target_periods": 1, "windows_per_point": 1, "sweet_max_gap": 0,
                "sweet_min_points": 1, "seed": 0}
        for name, low in ints.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {v!r}")
            set_(self, name, int(v))
        if self.record_periods < self.target_periods + 2:
            raise ValueError(f"record_periods must be >= target_periods + 2 = "
                             f"{self.target_periods + 2}, got {self.record_periods!r}")
        modes = tuple(int(m) for m in np.atleast_1d(self.modes))
        if not modes or any(m not in (1, 2, 3) for m in modes):
            raise ValueError(f"modes must be a non-empty sequence of 1, 2, 3, got {self.modes!r}")
        set_(self, "modes", modes)
        for name in ("sweet_spot_fraction", "near_six_fraction", "nonuniform_fraction",
                     "tip_fraction", "sweet_spot_tip_fraction", "exact_six_fraction"):
            set_(self, name, _in_range(name, getattr(self, name), 0.0, 1.0))
        if self.sweet_spot_fraction + self.nonuniform_fraction > 1.0 + 1e-12:
            raise ValueError("sweet_spot_fraction + nonuniform_fraction must be <= 1, got "
                             f"{self.sweet_spot_fraction} + {self.nonuniform_fraction}")
        if self.sweeps_per_cantilever + self.series_per_cantilever < 1:
            raise ValueError("sweeps_per_cantilever + series_per_cantilever must be >= 1")
        if self.series_per_cantilever and self.series_periods < self.target_periods + 2:
            raise ValueError(f"series_periods must be >= target_periods + 2 = "
                             f"{self.target_periods + 2}, got {self.series_periods!r}")
        for name in ("ratio2_range", "lowpass_range"):
            v = tuple(float(r) for r in np.atleast_1d(getattr(self, name)))
            if v:
                set_(self, name, _pair(name, v))
            else:
                set_(self, name, ())
        spp = tuple(int(v) for v in np.atleast_1d(self.sim_samples_choices))
        if any(v < 40 for v in spp):
            raise ValueError(f"sim_samples_choices must hold integers >= 40, got {spp!r}")
        set_(self, "sim_samples_choices", spp)
        bits = tuple(int(v) for v in np.atleast_1d(self.adc_bits))
        if any(not 8 <= v <= 24 for v in bits):
            raise ValueError(f"adc_bits must hold integers in [8, 24], got {bits!r}")
        set_(self, "adc_bits", bits)
        for name in ("setpoint_range", "series_free_amplitude_range", "series_omega_range"):
            set_(self, name, _pair(name, getattr(self, name)))
        set_(self, "series_settle_q", _in_range("series_settle_q", self.series_settle_q, 0.0,
                                                math.inf))
        away = tuple(float(r) for r in np.atleast_1d(self.away_ratios))
        if not away or any(not (math.isfinite(r) and r > 1.0) for r in away):
            raise ValueError(f"away_ratios must hold values > 1, got {self.away_ratios!r}")
        set_(self, "away_ratios", away)
        for name in ("q_range", "higher_q_range", "free_amplitude_range"):
            set_(self, name, _pair(name, getattr(self, name)))
        start = _in_range("omega_start", self.omega_start, 0.0, math.inf, low_open=True)
        stop = _in_range("omega_stop", self.omega_stop, start, math.inf, low_open=True)
        set_(self, "omega_start", start)
        set_(self, "omega_stop", stop)
        for name in ("settle_periods", "initial_settle_periods"):
            set_(self, name, _in_range(name, getattr(self, name), 0.0, math.inf))
        noise = tuple(float(v) for v in np.atleast_1d(self.noise_levels))
        if not noise or any(not 0.0 <= v <= 1.0 for v in noise):
            raise ValueError(f"noise_levels must hold values in [0, 1], got {self.noise_levels!r}")
        set_(self, "noise_levels", noise)
        set_(self, "coupling_threshold", _in_range("coupling_threshold", self.coupling_threshold,
                                                   0.0, 1.0, low_open=True, high_open=True))

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> DatasetSpec:
        """Build from a mapping (e.g. a Hydra config node); unknown keys raise ``ValueError``."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"spec: unknown key(s) {unknown}; allowed: {sorted(known)}")
        return cls(**{k: (tuple(v) if isinstance(v, Sequence) and not isinstance(v, str) else v)
                      for k, v in values.items()})

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable values (tuples become lists)."""
        return json.loads(json.dumps(dataclasses.asdict(self)))

    @property
    def hash(self) -> str:
        """SHA-256 of the spec and of :data:`GENERATOR_VERSION` (hex)."""
        text = json.dumps({"spec": self.to_dict(), "generator": GENERATOR_VERSION},
                          sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    @property
    def n_sweeps(self) -> int:
        """Records in total: sweep directions (2 per sweep) and set-point series."""
        return self.n_cantilevers * (2 * self.sweeps_per_cantilever
                                     + self.series_per_cantilever)

    @property
    def n_windows(self) -> int:
        """Windows in the dataset."""
        per_cantilever = (2 * self.sweeps_per_cantilever * self.n_points
                          + self.series_per_cantilever * self.n_setpoints)
        return self.n_cantilevers * per_cantilever * self.windows_per_point


def _in_range(name: str, value: Any, low: float, high: float, *, low_open: bool = False,
              high_open: bool = False) -> float:
    v = float(value)
    ok = (math.isfinite(v) or high == math.inf and v == math.inf) and (
        v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not ok or not math.isfinite(v):
        lo, hi = "(" if low_open else "[", ")" if high_open else "]"
        raise ValueError(f"{name} must lie in {lo}{low:g}, {high:g}{hi}, got {value!r}")
    return v


def _pair(name: str, value: Any) -> tuple[float, float]:
    a = np.asarray(value, dtype=float).reshape(-1)
    if a.shape != (2,) or not np.all(np.isfinite(a)) or a[0] <= 0 or a[1] < a[0]:
        raise ValueError(f"{name} must be (low, high) with 0 < low <= high, got {value!r}")
    return float(a[0]), float(a[1])


# ---------------------------------------------------------------------------- representation
def resample_windows(x: NDArray[np.float64], *, period: float, starts: NDArray[np.float64],
                     n_periods: int, samples_per_period: int) -> NDArray[np.float64]:
    """Cut windows of whole drive periods and resample them to a fixed grid (cubic spline).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Uniformly sampled signal (any unit).
    period : float
        Raw samples per drive period (``f_s / f_drive``), > 0.
    starts : ndarray, shape (W,)
        Window start positions in raw samples (fractional allowed).
    n_periods : int
        Periods per window.
    samples_per_period : int
        Output samples per period ``P``.

    Returns
    -------
    ndarray, shape (W, n_periods * P)
        ``x`` at ``start + k period / P``, ``k = 0 ... n_periods P - 1``.
    """
    starts = np.asarray(starts, dtype=float).reshape(-1)
    grid = np.arange(n_periods * samples_per_period) * (period / samples_per_period)
    t = starts[:, None] + grid[None, :]
    if starts.size and (t.min() < 0 or t.max() > x.shape[-1] - 1):
        raise ValueError(f"starts: windows of {n_periods} periods ({n_periods * period:.1f} "
                         f"samples) must lie inside the {x.shape[-1]} samples")
    spline = CubicSpline(np.arange(x.shape[-1], dtype=float), x)
    return spline(t)


def normalise_windows(w: NDArray[np.float64], samples_per_period: int
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Normalise windows by their first (input) period.

    Parameters
    ----------
    w : ndarray, shape (W, n)
        Resampled windows, input period first (``n >= samples_per_period``).
    samples_per_period : int

    Returns
    -------
    u : ndarray, shape (W, n)
        ``(w - m) / s``.
    offset : ndarray, shape (W,)
        ``m``, mean of the input period (unit of ``w``).
    scale : ndarray, shape (W,)
        ``s = sqrt(2) std`` of the input period (floored at 1e-12 times the largest ``|w|``
        to stay finite for a flat input).
    """
    first = w[:, :samples_per_period]
    offset = first.mean(axis=1)
    scale = math.sqrt(2.0) * first.std(axis=1)
    floor = 1e-12 * max(float(np.max(np.abs(w))) if w.size else 0.0, 1e-300)
    scale = np.maximum(scale, floor)
    return (w - offset[:, None]) / scale[:, None], offset, scale


def input_features(u_input: NDArray[np.floating], omega: NDArray[np.floating],
                   scale_over_gap: NDArray[np.floating]) -> NDArray[np.float32]:
    """Network input ``x`` from normalised input periods (see the module docstring).

    Parameters
    ----------
    u_input : ndarray, shape (W, P)
        Normalised input period.
    omega : ndarray, shape (W,)
        ``f_drive / f0``.
    scale_over_gap : ndarray, shape (W,)
        Normalisation scale ``s`` over the rest gap.

    Returns
    -------
    ndarray of float32, shape (W, P, 3)
        Channels: ``u``, ``10 (Omega - 1)``, ``s / gap``.
    """
    u_input = np.asarray(u_input)
    w, p = u_input.shape
    x = np.empty((w, p, N_FEATURES), dtype=np.float32)
    x[:, :, 0] = u_input
    x[:, :, 1] = (DETUNING_GAIN * (np.asarray(omega, dtype=float) - 1.0))[:, None]
    x[:, :, 2] = np.asarray(scale_over_gap, dtype=float)[:, None]
    return x


# ---------------------------------------------------------------------------- labels
def sweet_interval(omega: NDArray[np.float64], candidate: NDArray[np.bool_], *,
                   max_gap: int = 2, min_points: int = 2
                   ) -> tuple[tuple[float, float] | None, NDArray[np.bool_]]:
    """Sweet-spot interval of one sweep direction from per-point candidate flags.

    Parameters
    ----------
    omega : ndarray, shape (n,)
        Drive frequency of each point, in sweep order.
    candidate : ndarray of bool, shape (n,)
        Candidate points (labels: coupled and tapping; predictions: thresholded scores).
    max_gap : int
        Runs of at most this many non-candidates between candidates are bridged (>= 0).
    min_points : int
        A run needs at least this many candidates (>= 1).

    Returns
    -------
    interval : (float, float) or None
        ``(min Omega, max Omega)`` over the longest run (most candidates; ties: the earliest),
        None if there is none.
    mask : ndarray of bool, shape (n,)
        Points of the run (bridged gaps included).
    """
    omega = np.asarray(omega, dtype=float).reshape(-1)
    cand = np.asarray(candidate, dtype=bool).reshape(-1)
    if cand.shape != omega.shape:
        raise ValueError(f"candidate must have the shape of omega {omega.shape}, got "
                         f"{cand.shape}")
    mask = np.zeros(omega.shape, dtype=bool)
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        return None, mask
    breaks = np.flatnonzero(np.diff(idx) > max_gap + 1)
    firsts = np.concatenate([[0], breaks + 1])
    lasts = np.concatenate([breaks, [idx.size - 1]])
    counts = lasts - firsts + 1
    best = int(np.argmax(counts))
    if counts[best] < min_points:
        return None, mask
    lo, hi = int(idx[firsts[best]]), int(idx[lasts[best]])
    mask[lo:hi + 1] = True
    return (float(omega[mask].min()), float(omega[mask].max())), mask


# ---------------------------------------------------------------------------- cantilevers
def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _draw_ratio2(spec: DatasetSpec, rng: np.random.Generator) -> float:
    """Mode-2 frequency ratio: near 6:1 (exactly 6 for a share), else away or in a range."""
    if rng.uniform() < spec.near_six_fraction:
        if rng.uniform() < spec.exact_six_fraction:
            return 6.0
        return 6.0 * math.sqrt(1.0 + rng.uniform(-0.03, 0.03))
    if spec.ratio2_range:
        return float(rng.uniform(*spec.ratio2_range))
    return float(rng.choice(spec.away_ratios))


def _family(spec: DatasetSpec, index: int) -> tuple[str, int]:
    """Family of cantilever ``index`` and its position within the family."""
    n_sweet = int(round(spec.sweet_spot_fraction * spec.n_cantilevers))
    n_nonuniform = int(round(spec.nonuniform_fraction * spec.n_cantilevers))
    if index < n_sweet:
        return "sweet_spot", index
    if index < n_sweet + n_nonuniform:
        return "nonuniform", index - n_sweet
    return "rectangular", index - n_sweet - n_nonuniform


def _draw_cantilever(spec: DatasetSpec, index: int, rng: np.random.Generator
                     ) -> tuple[dict[str, Any], Cantilever, DMT, type]:
    """Family, parameters, cantilever, force and excitation class of cantilever ``index``.

    Families: ``sweet_spot`` (Table 3.B.1 fit; base excitation, tip for a share
    ``sweet_spot_tip_fraction``), ``rectangular`` (beam theory: mode 3 at 17.55, mode shapes of
    a uniform beam) and ``nonuniform`` (a beam with a tip mass / taper: mode 3 at 14 ... 16.5,
    other modal force gains and base participations, wider contact parameters).
    """
    family, k = _family(spec, index)
    if family == "sweet_spot":
        k2 = 36.0 * (1.0 + rng.uniform(-0.03, 0.03))
        d = np.array(_TABLE_DAMPING) * rng.uniform(0.8, 1.25, 2)
        dc = np.array(_TABLE_CONTACT_DAMPING) * rng.uniform(0.8, 1.25, 2)
        cl = Cantilever(stiffness=[1.0, k2], damping=d, contact_damping=dc,
                        base_participation=_TABLE_BASE, force_gain=[1.0, _TABLE_GAIN])
        force = DMT(a0=0.2, vdw=6e-4 * rng.uniform(0.7, 1.2), stiffness=10.5, exponent=1.5)
        exc = TipExcitation if rng.uniform() < spec.sweet_spot_tip_fraction else BaseExcitation
        params = {"family": family, "n_modes": 2, "ratio2": math.sqrt(k2),
                  "cantilever": cl.to_dict(), "force": force.to_dict(), "excitation": exc.kind}
        return params, cl, force, exc
    n_modes = spec.modes[k % len(spec.modes)]
    q1 = _loguniform(rng, *spec.q_range)
    ratios = [1.0]
    if n_modes >= 2:
        ratios.append(_draw_ratio2(spec, rng))
    if n_modes == 3:
        ratios.append(17.55 * (1.0 + rng.uniform(-0.02, 0.02)) if family == "rectangular"
                      else float(rng.uniform(14.0, 16.5)))
    qh = [_loguniform(rng, *spec.higher_q_range) for _ in range(n_modes - 1)]
    qc = [q1 / rng.uniform(1.5, 2.5)] + [q / rng.uniform(4.0, 16.0) for q in qh]
    if family == "rectangular":
        cl = Cantilever.rectangular(n_modes=n_modes, quality_factor=q1,
                                    higher_quality_factors=qh, contact_quality_factors=qc,
                                    frequency_ratios=ratios)
        force = DMT(a0=0.2, vdw=_loguniform(rng, 1e-4, 8e-4),
                    stiffness=_loguniform(rng, 6.0, 20.0), exponent=1.5)
    else:
        r = np.asarray(ratios)
        q = np.asarray([q1, *qh])
        gain = [1.0, rng.uniform(0.7, 1.5), rng.uniform(0.6, 1.3)][:n_modes]
        base = [rng.uniform(1.3, 1.8), -rng.uniform(0.5, 1.2), rng.uniform(0.3, 0.7)][:n_modes]
        cl = Cantilever(stiffness=r**2, damping=r / q, contact_damping=r / np.asarray(qc),
                        base_participation=base, force_gain=gain)
        force = DMT(a0=float(rng.uniform(0.12, 0.3)), vdw=_loguniform(rng, 5e-5, 1.2e-3),
                    stiffness=_loguniform(rng, 4.0, 30.0), exponent=1.5)
    exc = TipExcitation if rng.uniform() < spec.tip_fraction else BaseExcitation
    params = {"family": family, "n_modes": n_modes,
              "ratio2": ratios[1] if n_modes >= 2 else 0.0, "cantilever": cl.to_dict(),
              "force": force.to_dict(), "excitation": exc.kind}
    return params, cl, force, exc


def _sensor(spec: DatasetSpec, rng: np.random.Generator, spp: float
            ) -> tuple[SensorChain, dict[str, float]]:
    """Detector chain of one record: noise, optional low-pass and ADC (drawn per record).

    ``spp``: raw samples per period of ``f0`` (the low-pass cut-off stays below 0.45 of the
    Nyquist frequency ``spp / 2``).
    """
    noise = float(rng.choice(spec.noise_levels))
    stages: list[Any] = [GaussianNoise(level=noise)]
    info = {"noise_level": noise, "lowpass_f0": 0.0, "adc_bits": 0.0}
    if spec.lowpass_range:
        cutoff = min(_loguniform(rng, *spec.lowpass_range), 0.45 * spp / 2.0)
        stages.append(LowPass(cutoff=cutoff, order=2))
        info["lowpass_f0"] = cutoff
    if spec.adc_bits:
        bits = int(rng.choice(spec.adc_bits))
        stages.append(Quantizer(bits=bits, full_scale=3.0))
        info["adc_bits"] = float(bits)
    return SensorChain(stages, seed=int(rng.integers(2**31))), info


def _measure(sensor: SensorChain, x: NDArray[np.float64], *, x_ref: float, dt: float,
             period: float) -> NDArray[np.float64]:
    """``sensor(x)`` without the start-up transient of a filter: the record is preceded by a
    copy of its first two drive periods (``period`` samples each; steady orbits repeat), which
    is cut off again."""
    n_pad = min(int(round(2.0 * period)), x.size)
    y = sensor(np.concatenate([x[:n_pad], x]), x_ref=x_ref, dt=dt)
    return y[n_pad:]


def _spp(spec: DatasetSpec, rng: np.random.Generator) -> int:
    if spec.sim_samples_choices:
        return int(rng.choice(spec.sim_samples_choices))
    return spec.sim_samples_per_period


# ---------------------------------------------------------------------------- one cantilever
def _simulate_cantilever(spec: DatasetSpec, index: int) -> dict[str, Any]:
    """All records of cantilever ``index`` (sweeps, then set-point series): per-point labels
    and resampled windows."""
    rng = np.random.default_rng([spec.seed, index])
    params, cl, force, exc_cls = _draw_cantilever(spec, index, rng)
    p_out = spec.samples_per_period
    n_win_periods = 1 + spec.target_periods
    points: dict[str, list] = {k: [] for k in (
        "omega", "sweep", "point_index", "coupling", "shares", "contact_fraction", "min_gap",
        "amplitude", "harmonic6")}
    windows: dict[str, list] = {k: [] for k in ("u", "omega", "scale", "offset", "point")}
    sweeps: dict[str, list] = {k: [] for k in ("direction", "free_amplitude", "noise_level",
                                                "samples_per_period", "lowpass_f0", "adc_bits")}

    def add_point(q, phase, dt, omega, labels, x_meas, row, k, gap):
        var = q.var(axis=1)
        shares = np.zeros(3)
        shares[: q.shape[0]] = var / var.sum() if var.sum() > 0 else 0.0
        x_true = q.sum(axis=0)
        n_whole = int(math.floor(x_true.size * dt * omega / (2 * math.pi))
                      * (2 * math.pi / omega) / dt)
        x1 = abs(lock_in(x_true[:n_whole], phase[:n_whole], 1))
        x6 = abs(lock_in(x_true[:n_whole], phase[:n_whole], 6))
        n_point = len(points["omega"])
        for key, val in (("omega", omega), ("sweep", row), ("point_index", k),
                         ("coupling", coupling_strength(q)), ("shares", shares),
                         ("contact_fraction", labels["contact_fraction"]),
                         ("min_gap", labels["min_gap"]), ("amplitude", labels["amplitude"]),
                         ("harmonic6", x6 / x1 if x1 > 0 else 0.0)):
            points[key].append(val)
        period = 2.0 * math.pi / (omega * dt)
        room = x_meas.size - 1 - n_win_periods * period
        assert room > 0, "record too short for the window"
        starts = rng.uniform(0.0, room, spec.windows_per_point)
        w = resample_windows(x_meas, period=period, starts=starts, n_periods=n_win_periods,
                             samples_per_period=p_out)
        u, offset, scale = normalise_windows(w, p_out)
        windows["u"].append(u.astype(np.float32))
        windows["omega"].append(np.full(starts.size, omega))
        windows["scale"].append(scale / gap)  # units of the rest gap
        windows["offset"].append(offset)
        windows["point"].append(np.full(starts.size, n_point))

    def add_record(direction, free_amp, info, spp):
        sweeps["direction"].append(DIRECTIONS.index(direction))
        sweeps["free_amplitude"].append(free_amp)
        sweeps["samples_per_period"].append(float(spp))
        for key in ("noise_level", "lowpass_f0", "adc_bits"):
            sweeps[key].append(info[key])

    def sweet_spot_free_amplitude(omega: float) -> float:
        return BaseExcitation(amplitude=_TABLE_DITHER * rng.uniform(0.9, 1.1)
                              ).free_amplitude(cl, omega)

    n_rows = 0
    for _ in range(spec.sweeps_per_cantilever):
        if params["family"] == "sweet_spot" and exc_cls is BaseExcitation:
            exc = BaseExcitation(amplitude=_TABLE_DITHER * rng.uniform(0.9, 1.1))
        elif params["family"] == "sweet_spot":
            exc = exc_cls.for_free_amplitude(cl, 1.0, sweet_spot_free_amplitude(1.0))
        else:
            exc = exc_cls.for_free_amplitude(cl, 1.0, rng.uniform(*spec.free_amplitude_range))
        free_amp = exc.free_amplitude(cl, 1.0)
        spp = _spp(spec, rng)
        sensor, info = _sensor(spec, rng, spp)
        sweep = Sweep(omega_start=spec.omega_start, omega_stop=spec.omega_stop,
                      n_points=spec.n_points, samples_per_point=spec.record_periods * spp,
                      settle_samples=int(round(spec.settle_periods * spp)), direction="both",
                      samples_per_period=spp, settle_periods=spec.initial_settle_periods,
                      integrator=RK4(steps_per_period=spec.steps_per_period))
        system = System(cl, force, exc)
        for direction in DIRECTIONS[:2]:
            add_record(direction, free_amp, info, spp)
        for pt in sweep.iter_points(system):
            x_meas = _measure(sensor, pt.q.sum(axis=0), x_ref=free_amp, dt=sweep.dt,
                              period=2.0 * math.pi / (pt.omega * sweep.dt))
            add_point(pt.q, pt.phase, sweep.dt, pt.omega, pt.labels, x_meas,
                      n_rows + DIRECTIONS.index(pt.direction), pt.row % spec.n_points, 1.0)
        n_rows += 2
    q1 = float(cl.quality_factors[0])
    for _ in range(spec.series_per_cantilever):
        omega = float(rng.uniform(*spec.series_omega_range))
        if params["family"] == "sweet_spot" and exc_cls is BaseExcitation:
            exc = BaseExcitation(amplitude=_TABLE_DITHER * rng.uniform(0.9, 1.1))
        elif params["family"] == "sweet_spot":
            exc = exc_cls.for_free_amplitude(cl, omega, sweet_spot_free_amplitude(omega))
        else:
            exc = exc_cls.for_free_amplitude(cl, omega,
                                             rng.uniform(*spec.series_free_amplitude_range))
        free_amp = exc.free_amplitude(cl, omega)
        spp = _spp(spec, rng)                     # samples per drive period here
        sensor, info = _sensor(spec, rng, spp * omega)
        ratios = np.sort(rng.uniform(*spec.setpoint_range, spec.n_setpoints))[::-1]
        scen = Spectroscopy(omega=omega, gap_ratios=ratios, n_periods=spec.series_periods,
                            settle_periods=spec.series_settle_q * q1, samples_per_period=spp,
                            integrator=RK4(steps_per_period=spec.steps_per_period))
        res = scen.run(System(cl, force, exc))
        gaps = scen.rest_gaps(free_amp)
        add_record("series", free_amp, info, spp)
        for i in range(gaps.size):
            labels = {key: res.labels[key][i] for key in ("contact_fraction", "min_gap",
                                                           "amplitude")}
            x_meas = _measure(sensor, res.q[i].sum(axis=0), x_ref=free_amp, dt=res.dt,
                              period=float(spp))
            add_point(res.q[i], res.phase[i], res.dt, omega, labels, x_meas, n_rows, i,
                      float(gaps[i]))
        n_rows += 1
    out: dict[str, Any] = {"params_json": json.dumps(params)}
    for key, vals in points.items():
        out["points/" + key] = np.asarray(vals)
    for key, vals in windows.items():
        out["windows/" + key] = np.concatenate(vals)
    for key, vals in sweeps.items():
        out["sweeps/" + key] = np.asarray(vals)
    return out


def _label_points(spec: DatasetSpec, points: dict[str, NDArray], direction: NDArray
                  ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """``coupled``, ``sweet`` per point and the sweet interval ``(lo, hi)`` per sweep.

    A set-point series (one drive frequency) has no interval; its ``sweet`` points are the
    candidates themselves (coupled and tapping)."""
    n_sweeps = direction.size
    coupled = points["coupling"] > spec.coupling_threshold
    cand = coupled & (points["contact_fraction"] > 0.0)
    sweet = np.zeros_like(coupled)
    lo = np.full(n_sweeps, np.nan)
    hi = np.full(n_sweeps, np.nan)
    for s in range(n_sweeps):
        rows = np.flatnonzero(points["sweep_id"] == s)
        if DIRECTIONS[int(direction[s])] == "series":
            sweet[rows] = cand[rows]
            continue
        rows = rows[np.argsort(points["point_index"][rows])]
        interval, mask = sweet_interval(points["omega"][rows], cand[rows],
                                        max_gap=spec.sweet_max_gap,
                                        min_points=spec.sweet_min_points)
        sweet[rows] = mask
        if interval is not None:
            lo[s], hi[s] = interval
    return coupled, sweet, lo, hi


# ---------------------------------------------------------------------------- cache
def _save_npz(path: Path, arrays: dict[str, Any]) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **{k.replace("/", "__"): v for k, v in arrays.items()})


def _load_npz(path: Path) -> dict[str, Any]:
    with np.load(path) as z:
        return {k.replace("__", "/"): (str(z[k]) if k == "params_json" else z[k]) for k in z}


def _cached_hash(path: Path) -> str | None:
    try:
        with h5py.File(path, "r") as fh:
            if fh.attrs.get("format") != _FORMAT:
                return None
            return str(fh.attrs.get("spec_hash"))
    except (OSError, KeyError):
        return None


def generate_dataset(path: str | os.PathLike[str], *, spec: DatasetSpec,
                     progress: bool = True) -> Path:
    """Simulate the dataset of ``spec`` into the HDF5 file ``path`` (reused when cached).

    Parameters
    ----------
    path : str or os.PathLike
        Output file. If it exists with the same ``spec_hash`` it is returned untouched; a file
        with another hash is regenerated (a warning is logged).
    spec : DatasetSpec
    progress : bool
        Show a progress bar over cantilevers.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    if not isinstance(spec, DatasetSpec):
        raise ValueError(f"spec must be a DatasetSpec, got {type(spec).__name__}")
    path = Path(path)
    digest = spec.hash
    if path.exists():
        if _cached_hash(path) == digest:
            return path
        log.warning("%s holds another dataset spec; regenerating it", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    parts = path.with_name(path.name + ".parts")
    parts.mkdir(exist_ok=True)
    t0 = time.perf_counter()
    indices = range(spec.n_cantilevers)
    if progress:
        from tqdm.auto import tqdm
        indices = tqdm(indices, desc="qrnn dataset (cantilevers)")
    shards = []
    for i in indices:
        shard = parts / f"cantilever-{i:05d}-{digest[:16]}.npz"
        if not shard.exists():
            _save_npz(shard, _simulate_cantilever(spec, i))
        shards.append(shard)
    seconds = time.perf_counter() - t0
    _assemble(path, spec, [_load_npz(s) for s in shards], seconds)
    shutil.rmtree(parts, ignore_errors=True)
    return path


def _assemble(path: Path, spec: DatasetSpec, parts: list[dict[str, Any]],
              seconds: float) -> None:
    """Concatenate the per-cantilever parts, label them and write the HDF5 file atomically."""
    points: dict[str, list] = {}
    windows: dict[str, list] = {}
    sweeps: dict[str, list] = {}
    n_points = n_sweeps = 0
    cant_ids_s, params = [], []
    for c, part in enumerate(parts):
        n_p = part["points/omega"].size
        n_s = part["sweeps/direction"].size
        for key, val in part.items():
            group, _, name = key.partition("/")
            if group == "points":
                val = val + n_sweeps if name == "sweep" else val
                points.setdefault("sweep_id" if name == "sweep" else name, []).append(val)
            elif group == "windows":
                windows.setdefault(name, []).append(val + n_points if name == "point" else val)
            elif group == "sweeps":
                sweeps.setdefault(name, []).append(val)
        points.setdefault("cantilever_id", []).append(np.full(n_p, c))
        cant_ids_s.append(np.full(n_s, c))
        params.append(json.loads(part["params_json"]))
        n_points += n_p
        n_sweeps += n_s
    pts = {k: np.concatenate(v) for k, v in points.items()}
    win = {k: np.concatenate(v) for k, v in windows.items()}
    swp = {k: np.concatenate(v) for k, v in sweeps.items()}
    coupled, sweet, lo, hi = _label_points(spec, pts, swp["direction"])
    pts["coupled"], pts["sweet"] = coupled, sweet
    swp["cantilever_id"] = np.concatenate(cant_ids_s)
    n_modes = np.array([p["n_modes"] for p in params])
    family = np.array([FAMILIES.index(p["family"]) for p in params])
    excitation = np.array([EXCITATIONS.index(p["excitation"]) for p in params])
    swp["n_modes"] = n_modes[swp["cantilever_id"]]
    swp["family"] = family[swp["cantilever_id"]]
    swp["excitation"] = excitation[swp["cantilever_id"]]
    swp["sweet_lo"], swp["sweet_hi"] = lo, hi
    pidx = win["point"]
    for key in ("cantilever_id", "sweep_id", "point_index", "coupling", "coupled", "sweet",
                "shares"):
        win[key] = pts[key][pidx]
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as fh:
        fh.attrs.update({
            "format": _FORMAT, "format_version": 1, "spec_hash": spec.hash,
            "spec_json": json.dumps(spec.to_dict()), "generator_version": GENERATOR_VERSION,
            "generation_seconds": seconds, "n_cantilevers": len(parts),
            "n_sweeps": n_sweeps, "n_points": n_points, "n_windows": pidx.size,
            "samples_per_period": spec.samples_per_period,
            "target_periods": spec.target_periods, "n_features": N_FEATURES,
        })
        for group, arrays in (("points", pts), ("windows", win), ("sweeps", swp)):
            g = fh.create_group(group)
            for key, val in arrays.items():
                val = np.asarray(val)
                if val.dtype == np.float64 and key not in ("omega", "sweet_lo", "sweet_hi"):
                    val = val.astype(np.float32)
                g.create_dataset(key, data=val)
        g = fh.create_group("cantilevers")
        g.create_dataset("n_modes", data=n_modes)
        g.create_dataset("family", data=family)
        g.create_dataset("excitation", data=excitation)
        g.create_dataset("ratio2", data=np.array([p["ratio2"] for p in params]))
        g.attrs["params_json"] = json.dumps(params)


def dataset_summary(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Counts and label balance of a generated dataset (for reports and docs)."""
    with h5py.File(path, "r") as fh:
        pts = {k: fh["points"][k][()] for k in ("coupling", "coupled", "sweet")}
        swp_lo = fh["sweeps/sweet_lo"][()]
        out = {k: int(fh.attrs[k]) for k in ("n_cantilevers", "n_sweeps", "n_points",
                                             "n_windows")}
        out["generation_seconds"] = float(fh.attrs["generation_seconds"])
        out["size_mb"] = os.path.getsize(path) / 1e6
    out["coupled_fraction"] = float(pts["coupled"].mean())
    out["sweet_fraction"] = float(pts["sweet"].mean())
    out["sweeps_with_sweet_spot"] = int(np.isfinite(swp_lo).sum())
    out["coupling_quantiles"] = np.quantile(pts["coupling"], [0.5, 0.9, 0.99]).tolist()
    return out
