"""The observations a diagnosis fits: steady records (set-points) and windows of a ramp.

An experiment's observations share the cantilever and the tip--sample law. Each is
calibrated (:func:`afmlearn.preprocess.calibrate`; the labels are never read) and then
rescaled to one common length ``L_ref`` (the mean rest gap over the experiment), so that one
dimensionless force law holds for all of them.

A ramp (``gap_m`` of shape (n,)) is cut into windows of a few tens of drive periods, each
treated as a quasi-steady observation at the window's mean rest gap (the slowly varying gap
is known from the file). That is exact when the gap changes little over the lever's settling
time (the amplitude time constant ``2 Q / omega0``, ``Q / pi`` periods): the orbit lags the
quasi-steady one by about the gap change over that time, ``Observation.ramp_lag``. Above 2 % of
``L_ref`` a warning says so; above :data:`MAX_RAMP_LAG` the windows' bias is larger than the
effects the diagnosis looks for, and it names no cause (measured on plain-DMT ramps,
docs/diagnose.md "Ramps").
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io import Experiment, Trace
from afmlearn.preprocess import Calibrated, calibrate, check_trace
from simulator import Scales

from .joint import PhasePrior

__all__ = ["Observation", "MAX_RAMP_LAG", "build_observations", "as_traces", "folds",
           "drive_groups", "read_experiment"]

FloatArray = NDArray[np.float64]

#: largest gap change per settling time (``Q / pi`` periods, in ``L_ref``) at which a ramp's
#: windows are diagnosed for causes; faster ramps get the baseline only. Measured (default
#: config, tapping lever, seed 1, docs/diagnose.md "Ramps"): a visco-elastic ramp is named
#: right at lags 0.017 and 0.042 and wrongly (contact_geometry) at 0.085; a plain-DMT ramp
#: names nothing at 0.017 and 0.085, a false cause at 0.17, three at 0.56
MAX_RAMP_LAG = 0.05
#: lag above which the quasi-steady bias is worth a warning
_WARN_RAMP_LAG = 0.02

#: calibration fields every observation of one experiment must share
_SHARED = ("sample_rate_hz", "spring_constant_n_per_m", "quality_factor",
           "resonance_frequency_hz", "excitation")


@final
@dataclass(frozen=True, eq=False)
class Observation:
    """One quasi-steady record at one rest gap, in the experiment's common units.

    Attributes
    ----------
    index : int
        Position of the source record in the experiment.
    kind : {"steady", "ramp_window"}
    cal : Calibrated
        The record (the whole ramp for a window), rescaled to the common ``L_ref``.
    start, stop : int
        Sample range of this observation in ``cal``.
    gap : float
        Rest gap / ``L_ref`` (a window's mean).
    phase_prior : (float, float) or None
        Recorded drive phase in the model's convention (``B cos(Omega tau - phi)``, ``tau``
        from the record's first sample: ``phi = -drive_phase_rad``) and its standard
        deviation [rad]; None when not recorded.
    trace : Trace
        The 1-D source record (for evidence that reads raw data, e.g. the QRNN score).
    ramp_lag : float
        A ramp window's gap change over the lever's settling time (``Q / pi`` drive
        periods), in ``L_ref``: the quasi-steady approximation's error in the gap; 0 for a
        steady record.
    """

    index: int
    kind: Literal["steady", "ramp_window"]
    cal: Calibrated
    start: int
    stop: int
    gap: float
    phase_prior: PhasePrior | None
    trace: Trace
    ramp_lag: float = 0.0

    @property
    def gap_m(self) -> float:
        return self.gap * self.cal.scales.length

    @property
    def tau(self) -> FloatArray:
        return self.cal.tau[self.start:self.stop]

    @property
    def x(self) -> FloatArray:
        return self.cal.x[self.start:self.stop]

    @property
    def n_periods(self) -> float:
        return (self.stop - self.start) / self.cal.samples_per_period


def as_traces(data: Any, row: int | None = None) -> list[Trace]:
    """The 1-D records of ``data``: an ``afmlearn.io.Experiment``, a Trace or a list of them.

    A set-point series gives one record per row; a sweep needs ``row`` (its rows are
    different drive frequencies, diagnosed one at a time); ``row`` picks one row of either.
    """
    if isinstance(data, Trace):
        if data.has_rows:
            if row is not None:
                return [data.row(row)]
            if data.is_sweep:
                raise ValueError(f"row must be given for a sweep (an integer in "
                                 f"[0, {data.n_points})): its rows are different drive "
                                 f"frequencies")
            return [data.row(i) for i in range(data.n_points)]
        if row not in (None, 0):
            raise ValueError(f"row must be None (or 0) for a single trace, got {row!r}")
        return [data]
    if isinstance(data, Sequence) or hasattr(data, "__iter__"):
        out = list(data)
        if out and all(isinstance(t, Trace) and not t.has_rows for t in out):
            if row is not None:
                if isinstance(row, bool) or not isinstance(row, int) \
                        or not 0 <= row < len(out):
                    raise ValueError(f"row must be an integer in [0, {len(out)}), got {row!r}")
                return [out[row]]
            return out
    raise ValueError(f"data must be an afmlearn.io.Experiment, a Trace or a list of 1-D "
                     f"Traces, got {type(data).__name__}")


def read_experiment(paths: Sequence[str | os.PathLike[str]]) -> Experiment:
    """One experiment from several trace files of one tip (e.g. set-point series recorded at
    two free amplitudes): every row of every file, in order; ``/labels`` is never opened.

    Parameters
    ----------
    paths : sequence of str or os.PathLike
        At least one trace file (format v1, or an instrument file); no sweep (its rows are
        different drive frequencies: diagnosed one row at a time).

    Raises
    ------
    ValueError
        No path, a sweep, or files that do not share the cantilever's calibration (the
        message names the field); afmlearn.io.TraceFormatError for a file that is not a trace.
    """
    if isinstance(paths, (str, os.PathLike)) or not len(paths):
        raise ValueError(f"trace must be a non-empty list of trace files, got {paths!r}")
    rows: list[Trace] = []
    for p in paths:
        exp = Experiment.read(p)                 # labels=False: /labels never opened
        if exp.kind == "sweep":
            raise ValueError(f"trace: {os.fspath(p)} is a frequency sweep; its rows are "
                             f"diagnosed one at a time (one file and row=...)")
        rows += list(exp)
    try:
        return Experiment(rows)
    except ValueError as err:
        raise ValueError(f"trace: the files are not one cantilever's: {err}") from None


def _check_shared(traces: Sequence[Trace]) -> None:
    first = traces[0]
    for t in traces[1:]:
        for name in _SHARED:
            a, b = getattr(first, name), getattr(t, name)
            if a != b and not (isinstance(a, float) and isinstance(b, float)
                               and math.isclose(a, b, rel_tol=1e-9)):
                raise ValueError(f"observations must share {name}: {a!r} != {b!r}")


def _rescale(cal: Calibrated, length: float) -> Calibrated:
    """``cal`` in units of ``length`` instead of its own mean rest gap."""
    f = cal.scales.length / length

    def s(v: Any) -> Any:
        if v is None:
            return None
        out = np.asarray(v, float) * f
        if out.ndim == 0:
            return float(out)
        out.flags.writeable = False
        return out

    return dataclasses.replace(
        cal, x=s(cal.x), gap=s(cal.gap), drive_amplitude=s(cal.drive_amplitude),
        dither=s(cal.dither), tip_radius=s(cal.tip_radius),
        scales=Scales(spring_constant=cal.scales.spring_constant,
                      resonance_frequency=cal.scales.resonance_frequency, length=length))


def build_observations(traces: Sequence[Trace], *, phase_sd: float, window_periods: float,
                       max_windows: int, warnings: list[str]) -> list[Observation]:
    """Check, calibrate and rescale every record; cut ramps into windows.

    Parameters
    ----------
    traces : sequence of Trace
        1-D records sharing the calibration (:func:`as_traces`).
    phase_sd : float
        Standard deviation [rad] given to a recorded drive phase.
    window_periods : float
        Length of a ramp window in drive periods.
    max_windows : int
        Most windows taken from one ramp (spread evenly over it).
    warnings : list of str
        Appended to.
    """
    if not traces:
        raise ValueError("data: the experiment has no observations")
    _check_shared(traces)
    cals = []
    for t in traces:
        check_trace(t)
        cals.append(calibrate(t))
    length = float(np.mean([c.scales.length for c in cals]))
    out: list[Observation] = []
    base_excitation = traces[0].excitation == "base"
    for i, (t, c) in enumerate(zip(traces, cals, strict=True)):
        c = _rescale(c, length)
        prior = None
        if t.drive_phase_rad is not None:
            if base_excitation:
                if i == 0:
                    warnings.append("base excitation: the recorded drive phase is the "
                                    "dither's, not the modal force's; it is fitted instead")
            else:
                prior = (-float(np.asarray(t.drive_phase_rad).reshape(-1)[0]), float(phase_sd))
        if np.ndim(c.gap) == 0:
            out.append(Observation(i, "steady", c, 0, c.n_samples, float(c.gap), prior, t))
            continue
        out += _windows(i, t, c, prior, window_periods, max_windows, warnings)
    return out


def _windows(i: int, t: Trace, c: Calibrated, prior: PhasePrior | None, window_periods: float,
             max_windows: int, warnings: list[str]) -> list[Observation]:
    """Quasi-steady windows of a ramp record, at most ``max_windows``, evenly spread."""
    spp = c.samples_per_period
    w = int(round(window_periods * spp))
    n_win = int(c.n_samples // w)
    if n_win < 1:
        raise ValueError(f"data: the ramp of observation {i} spans "
                         f"{c.n_samples / spp:.1f} drive periods; a ramp window needs "
                         f"{window_periods:g}")
    gap = np.asarray(c.gap, float)
    picks = np.unique(np.round(np.linspace(0, n_win - 1, min(n_win, max_windows))).astype(int))
    # largest gap change over one settling time (Q/pi periods), in L_ref: a difference over
    # that span (half the record if shorter, scaled), not a sample-to-sample slope (a
    # measured Z-sensor gap's noise would be amplified by the samples per settling time)
    settle = c.quality_factor / math.pi
    m = min(max(1, int(round(settle * spp))), gap.size // 2)
    lag = (float(np.max(np.abs(gap[m:] - gap[:-m]))) * settle * spp / m) if m >= 1 else 0.0
    rate = lag / settle                      # L_ref per drive period
    if lag > _WARN_RAMP_LAG:
        # rate [L_ref per period] in SI: L_ref [m] x drive frequency [Hz]
        si = c.scales.length * c.omega * c.scales.resonance_frequency
        warnings.append(
            f"observation {i}: the ramp moves the gap by {100 * lag:.1f} % of L_ref "
            f"({c.scales.length * 1e9:.3g} nm) per settling time (Q/pi = {settle:.0f} "
            f"periods; {rate * si * 1e9:.3g} nm/s); its windows are treated as quasi-steady, "
            f"which biases them"
            + ("" if lag <= MAX_RAMP_LAG else
               f"; above the {100 * MAX_RAMP_LAG:.0f} % limit (a ramp slower than "
               f"{MAX_RAMP_LAG / settle * si * 1e9:.3g} nm/s) no cause is named: the bias "
               f"exceeds the effects sought, and the force law and contact exponent are "
               f"biased too"))
    out = []
    for k in picks:
        s, e = int(k * w), int((k + 1) * w)
        out.append(Observation(i, "ramp_window", c, s, e, float(np.mean(gap[s:e])), prior, t,
                               ramp_lag=lag))
    return out


def drive_groups(observations: Sequence[Observation], *, rel_tol: float = 1e-6
                 ) -> tuple[list[int], list[float | None]]:
    """Which observations share one drive amplitude ``B``, and each group's calibrated ``F_c``.

    Observations whose calibrated drive amplitudes (``cal.drive_amplitude``, k L_ref, from
    each record's free data) agree within ``rel_tol`` form one group: the rows of one
    set-point file and the windows of one ramp share their free record, so they share their
    ``F_c`` exactly; files recorded at different free amplitudes differ by their ratio.
    Observations without free data (``F_c`` None) join the single group when there is only
    one, else form a group of their own (its drive is then constrained by no calibration).

    Parameters
    ----------
    observations : sequence of Observation
        In the experiment's common units (:func:`build_observations`).
    rel_tol : float
        Relative tolerance of "the same" ``F_c``, > 0.

    Returns
    -------
    groups : list of int, length n_obs
        Group of each observation, numbered by first appearance (the first observation's
        group is 0).
    drives : list of float or None, length n_groups
        Each group's ``F_c`` [k L_ref]: the median of its members' (None: no free data).
    """
    if not rel_tol > 0:
        raise ValueError(f"rel_tol must be > 0, got {rel_tol!r}")
    fcs = [o.cal.drive_amplitude for o in observations]
    keys: list[float] = []          # one representative F_c per calibrated group
    member: list[int | None] = []
    for fc in fcs:
        if fc is None:
            member.append(None)
            continue
        for k, ref in enumerate(keys):
            if math.isclose(fc, ref, rel_tol=rel_tol):
                member.append(k)
                break
        else:
            keys.append(float(fc))
            member.append(len(keys) - 1)
    if len(keys) <= 1:
        # today's single drive: every observation, the median of the known F_c
        known = [float(fc) for fc in fcs if fc is not None]
        return [0] * len(fcs), [float(np.median(known)) if known else None]
    labels = ["none" if m is None else m for m in member]
    order: dict[int | str, int] = {}
    for lab in labels:
        order.setdefault(lab, len(order))
    groups = [order[lab] for lab in labels]
    drives: list[float | None] = [None] * len(order)
    for lab, g in order.items():
        if lab != "none":
            drives[g] = float(np.median([fc for fc, m in zip(fcs, member, strict=True)
                                         if m == lab]))
    return groups, drives


def folds(gaps: Sequence[float], max_folds: int) -> list[list[int]]:
    """Held-out groups of observations: one each (leave one out) when there are at most
    ``max_folds``, else ``max_folds`` groups interleaved in gap order (each spans the range).
    """
    n = len(gaps)
    order = np.argsort(np.asarray(gaps, float))
    k = min(n, max_folds)
    return [sorted(int(j) for j in order[f::k]) for f in range(k)]
