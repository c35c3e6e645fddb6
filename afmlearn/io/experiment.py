"""`Experiment`: the observations of one file that share the cantilever and the tip-sample law."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Sequence
from typing import Any, Literal, final, overload

import numpy as np

from afmlearn.io._checks import FloatArray
from afmlearn.io.reader import TraceReader
from afmlearn.io.trace import Trace

__all__ = ["Experiment", "EXPERIMENT_KINDS", "SHARED_FIELDS"]

Kind = Literal["single", "series", "sweep", "ramp", "curves"]
#: Values of `Experiment.kind`.
EXPERIMENT_KINDS: tuple[str, ...] = ("single", "series", "sweep", "ramp", "curves")
#: Metadata every observation of an experiment must share (the cantilever and its drive).
SHARED_FIELDS: tuple[str, ...] = (
    "sample_rate_hz",
    "spring_constant_n_per_m",
    "quality_factor",
    "resonance_frequency_hz",
    "excitation",
)
#: Optional metadata reported in `Experiment.calibration` when every observation agrees.
_COMMON_IF_EQUAL: tuple[str, ...] = (
    "free_amplitude_m",
    "dither_amplitude_m",
    "higher_mode_frequencies_hz",
    "tip_radius_m",
)
_RTOL = 1e-9  # relative tolerance of "the same calibration" (float round trips)


@final
class Experiment(Sequence[Trace]):
    """The observations of one file: one cantilever, one tip, one sample spot.

    Each observation is a 1-D `Trace`: a steady record at one rest gap, an approach/retract
    ramp (``gap_m`` of shape (n,)) or a lock-in curve. Analyses fit one tip-sample law to all
    observations and per-observation nuisances (drive phase when not recorded, the gap of a
    ramp) per observation. A single trace is an experiment of one.

    Parameters
    ----------
    observations : sequence of Trace
        At least one; each 1-D (use `from_trace` for a sweep or series). All must share
        `SHARED_FIELDS` (``sample_rate_hz``, ``spring_constant_n_per_m``, ``quality_factor``,
        ``resonance_frequency_hz``, ``excitation``).
    kind : {"single", "series", "sweep", "ramp", "curves"}, optional
        What the observations are; None infers it: "curves" if any is a lock-in curve, else
        "ramp" if any is a ramp, else "single" for one observation, "series" when all drive
        frequencies are equal and "sweep" otherwise.

    Raises
    ------
    ValueError
        Empty, not Traces, a 2-D trace among them, or a shared field that differs (the
        message names the field and the observation).

    Examples
    --------
    >>> exp = Experiment.read("series.h5")                     # doctest: +SKIP
    >>> exp.kind, len(exp), exp.gaps_m                         # doctest: +SKIP
    ('series', 8, array([...]))
    >>> held_out = [exp.subset([i]) for i in range(len(exp))]  # doctest: +SKIP
    """

    __slots__ = ("_kind", "_observations")

    def __init__(self, observations: Sequence[Trace], *, kind: Kind | None = None) -> None:
        if isinstance(observations, Trace):
            raise ValueError(
                "observations must be a sequence of Trace; wrap one trace with "
                "Experiment.from_trace(trace)"
            )
        obs = tuple(observations)
        if not obs:
            raise ValueError("observations must hold at least one Trace, got none")
        for i, trace in enumerate(obs):
            if not isinstance(trace, Trace):
                raise ValueError(
                    f"observations[{i}] must be an afmlearn.io.Trace, got {type(trace).__name__}"
                )
            if trace.has_rows:
                raise ValueError(
                    f"observations[{i}] has {trace.n_points} rows; each observation must be "
                    "1-D (use Experiment.from_trace for a sweep or a set-point series)"
                )
        _check_shared(obs)
        if kind is None:
            kind = _infer_kind(obs)
        elif kind not in EXPERIMENT_KINDS:
            raise ValueError(f"kind must be one of {EXPERIMENT_KINDS} or None, got {kind!r}")
        self._observations = obs
        self._kind: Kind = kind

    @classmethod
    def from_trace(cls, trace: Trace) -> Experiment:
        """One observation per row of a sweep or series; a 1-D trace gives an experiment of one.

        Parameters
        ----------
        trace : Trace
            Any trace; labels are kept (row labels for rows).
        """
        if not isinstance(trace, Trace):
            raise ValueError(f"trace must be an afmlearn.io.Trace, got {type(trace).__name__}")
        return cls([trace.row(i) for i in range(trace.n_points)], kind=_trace_kind(trace))

    @classmethod
    def read(cls, path: str | os.PathLike[str], *, labels: bool = False) -> Experiment:
        """Read a trace file as an experiment (rows of a sweep or series become observations).

        Parameters
        ----------
        path : str or os.PathLike
            A trace file (design.md section 2).
        labels : bool, default False
            Attach each observation's labels; with False the ``/labels`` group is never
            opened (analysis code under test must leave it False).

        Raises
        ------
        TraceFormatError
            If the file breaks the format.
        afmlearn.io.instruments.RecordingError
            For an instrument file that cannot be read (instrument files are opened with
            `afmlearn.io.instruments.open_traces`, one observation per curve).
        """
        from afmlearn.io.instruments import is_instrument_file, open_traces  # lazy: no cycle

        if is_instrument_file(path):
            return cls(open_traces(path))
        with TraceReader(path, labels=labels) as reader:
            rows = [reader.row(i) for i in range(reader.n_points)]
            if reader.has_rows:
                kind: Kind = "series" if reader.is_series else "sweep"
            else:
                kind = _trace_kind(rows[0])
        return cls(rows, kind=kind)

    @property
    def kind(self) -> Kind:
        """One of `EXPERIMENT_KINDS`: "single", "series", "sweep", "ramp" or "curves"."""
        return self._kind

    @property
    def observations(self) -> tuple[Trace, ...]:
        """The observations, each a 1-D `Trace`."""
        return self._observations

    def __len__(self) -> int:
        return len(self._observations)

    def __iter__(self) -> Iterator[Trace]:
        return iter(self._observations)

    @overload
    def __getitem__(self, index: int) -> Trace: ...

    @overload
    def __getitem__(self, index: slice) -> Experiment: ...

    def __getitem__(self, index: int | slice) -> Trace | Experiment:
        if isinstance(index, slice):
            return self.subset(range(len(self))[index])
        return self._observations[_index(index, len(self))]

    def __repr__(self) -> str:
        return f"Experiment(kind={self._kind!r}, n_observations={len(self)})"

    def subset(self, indices: Iterable[int]) -> Experiment:
        """The experiment of the observations ``indices`` (in that order), same kind.

        Parameters
        ----------
        indices : iterable of int
            Distinct observation indices, at least one (e.g. all but one set-point for a
            leave-one-set-point-out fit).
        """
        chosen = [_index(i, len(self)) for i in indices]
        if not chosen:
            raise ValueError("indices must select at least one observation, got none")
        if len(set(chosen)) != len(chosen):
            raise ValueError(f"indices must be distinct, got {chosen}")
        return Experiment([self._observations[i] for i in chosen], kind=self._kind)

    @property
    def gaps_m(self) -> FloatArray:
        """Rest gap of each observation [m], shape (n_obs,); NaN for ramps (gap varies)."""
        return np.array(
            [float(t.gap_m) if np.ndim(t.gap_m) == 0 else np.nan for t in self._observations]
        )

    @property
    def drive_phases_rad(self) -> FloatArray:
        """Recorded drive phase of each observation [rad], shape (n_obs,); NaN if not recorded."""
        return np.array(
            [np.nan if t.drive_phase_rad is None else float(t.drive_phase_rad)
             for t in self._observations]
        )

    @property
    def drive_frequencies_hz(self) -> FloatArray:
        """Drive frequency of each observation [Hz], shape (n_obs,)."""
        return np.array([float(t.drive_frequency_hz) for t in self._observations])

    @property
    def has_labels(self) -> bool:
        """True when every observation carries its labels (read with ``labels=True``)."""
        return all(t.labels is not None for t in self._observations)

    @property
    def calibration(self) -> dict[str, Any]:
        """The shared metadata: `SHARED_FIELDS`, plus ``free_amplitude_m``,
        ``dither_amplitude_m``, ``higher_mode_frequencies_hz`` and ``tip_radius_m`` when every
        observation has the same value (SI units, as in `Trace`)."""
        first = self._observations[0]
        out = {name: getattr(first, name) for name in SHARED_FIELDS}
        for name in _COMMON_IF_EQUAL:
            value = getattr(first, name)
            if value is not None and all(
                _same(value, getattr(t, name)) for t in self._observations[1:]
            ):
                out[name] = value
        return out


def _index(i: Any, n: int) -> int:
    if isinstance(i, bool) or not isinstance(i, int | np.integer):
        raise ValueError(f"index must be an integer in [-{n}, {n}), got {i!r}")
    if not -n <= i < n:
        raise ValueError(f"index must be in [-{n}, {n}), got {i}")
    return int(i) % n


def _same(a: Any, b: Any) -> bool:
    if a is None or b is None or isinstance(a, str) or isinstance(b, str):
        return a == b
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=_RTOL, atol=0.0))


def _check_shared(obs: tuple[Trace, ...]) -> None:
    first = obs[0]
    for i, trace in enumerate(obs[1:], start=1):
        for name in SHARED_FIELDS:
            a, b = getattr(first, name), getattr(trace, name)
            if not _same(a, b):
                raise ValueError(
                    f"{name} must be the same in every observation of an experiment: "
                    f"observations[0] has {a!r}, observations[{i}] has {b!r}"
                )


def _trace_kind(trace: Trace) -> Kind:
    if trace.is_series:
        return "series"
    if trace.is_sweep:
        return "sweep"
    if trace.is_curves:
        return "curves"
    if trace.is_ramp:
        return "ramp"
    return "single"


def _infer_kind(obs: tuple[Trace, ...]) -> Kind:
    if any(t.is_curves for t in obs):
        return "curves"
    if any(t.is_ramp for t in obs):
        return "ramp"
    if len(obs) == 1:
        return "single"
    drives = np.array([float(t.drive_frequency_hz) for t in obs])
    return "series" if np.allclose(drives, drives[0], rtol=_RTOL, atol=0.0) else "sweep"
