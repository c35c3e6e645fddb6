"""Writing trace files: `TraceWriter` streams rows to disk, `write_trace` writes a `Trace`."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any, final

import h5py
import numpy as np

from afmlearn.io._atomic import temporary_sibling
from afmlearn.io._checks import FloatArray, count, finite_array, finite_number
from afmlearn.io._format import (
    DEFLECTION,
    DRIVE_PHASE,
    EXTRA_GROUP,
    FORMAT,
    FORMAT_VERSION,
    LABELS_GROUP,
)
from afmlearn.io.labels import (
    check_effect,
    check_extra,
    check_model,
    check_name,
    check_scalar_shapes,
    check_scalars,
)
from afmlearn.io.trace import Trace, check_metadata

__all__ = ["TraceWriter", "write_trace"]

_BLOCK = 1 << 16  # chunk length [samples] of single (1-D) traces


@final
class TraceWriter:
    """Write one trace file a row (sweep, series) or a block of samples (1-D trace) at a time.

    The file is built in a hidden temporary file next to ``path``; datasets are chunked one
    row per chunk, so a 501 x 50,000 sweep is never held in memory. When the ``with`` block
    ends without an exception and every row (or sample) was written, the temporary file is
    renamed onto ``path`` atomically; otherwise it is deleted and ``path`` is left untouched.

    Parameters
    ----------
    path : str or os.PathLike
        Target file (``.h5``); an existing file is replaced.
    n_samples : int
        Samples per row, n >= 1.
    n_points : int, optional
        Rows of a sweep or set-point series (deflection shape (n_points, n)); None for a 1-D
        trace (n,).
    deflection : bool, default True
        False for lock-in curves without a deflection record: ``amplitude_m`` (n,) is then
        required in ``metadata``, nothing is appended and no labels are allowed.
    n_modes : int, default 0
        Number of modal deflections stored in the labels (0: none).
    model : dict, optional
        Model name and parameters (JSON-serialisable). Giving it marks a simulated file:
        a ``/labels`` group is written and every row needs ``force_n``.
    effect : str, default "none"
        Injected effect (labels only).
    scalars : dict of str to float, str or array of shape (n_points,), optional
        Per-trace label scalars known up front; per-row ones go to `write_row`.
    extra : dict of str to array, optional
        Further label arrays of any shape.
    **metadata
        The keyword fields of `Trace` other than ``deflection_m`` and ``labels``:
        ``sample_rate_hz``, ``spring_constant_n_per_m``, ``quality_factor``,
        ``resonance_frequency_hz``, ``drive_frequency_hz`` (array of shape (n_points,) for a
        sweep), ``gap_m`` (float, array of shape (n,), or (n_points,) for a series) are
        required; the others optional. ``drive_phase_rad`` may instead be given per row to
        `write_row`.

    Examples
    --------
    >>> with TraceWriter("sweep.h5", n_points=len(f_hz), n_samples=50_000,
    ...                  drive_frequency_hz=f_hz, **calibration) as writer:   # doctest: +SKIP
    ...     for i, f in enumerate(f_hz):
    ...         writer.write_row(i, simulate(f))
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        n_samples: int,
        n_points: int | None = None,
        deflection: bool = True,
        n_modes: int = 0,
        model: Mapping[str, Any] | None = None,
        effect: str = "none",
        scalars: Mapping[str, Any] | None = None,
        extra: Mapping[str, Any] | None = None,
        **metadata: Any,
    ) -> None:
        self._path = Path(path)
        if not self._path.parent.is_dir():
            raise ValueError(f"path: folder {self._path.parent} does not exist")
        self._n_samples = count("n_samples", n_samples, minimum=1)
        self._n_points = None if n_points is None else count("n_points", n_points, minimum=1)
        self._n_modes = count("n_modes", n_modes, minimum=0)
        self._metadata = check_metadata(
            n_points=self._n_points, n_samples=self._n_samples, **metadata
        )
        self._labelled = model is not None
        self._deflection = bool(deflection)
        if not self._deflection and (
            self._n_points is not None
            or self._metadata["amplitude_m"] is None
            or self._labelled
        ):
            raise ValueError(
                "deflection=False is for lock-in curves only: needs amplitude_m, a 1-D record "
                "(n_points=None) and no labels (model=None)"
            )
        if not self._labelled and (n_modes or scalars or extra or effect != "none"):
            raise ValueError(
                "model is required (it marks a file with labels) when n_modes, effect, "
                "scalars or extra are given"
            )
        self._model = check_model(model) if model is not None else None
        self._effect = check_effect(effect)
        self._scalars = check_scalars(scalars or {})
        check_scalar_shapes(self._scalars, self._shape)
        self._extra = check_extra(extra or {})
        self._row_scalars: tuple[str, ...] | None = None
        self._row_phase = False
        self._written = np.zeros(self._n_points or 0, dtype=bool)
        self._filled = 0
        self._tmp: Path | None = None
        self._file: h5py.File | None = None
        self._used = False

    @property
    def _shape(self) -> tuple[int, ...]:
        if self._n_points is None:
            return (self._n_samples,)
        return (self._n_points, self._n_samples)

    def __enter__(self) -> TraceWriter:
        if self._used:
            raise RuntimeError("a TraceWriter can be used in one `with` block only")
        self._used = True
        tmp = temporary_sibling(self._path)
        file = h5py.File(tmp, "w")
        try:
            self._create_layout(file)
        except BaseException:
            file.close()
            tmp.unlink(missing_ok=True)
            raise
        self._tmp, self._file = tmp, file
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        file, tmp = self._open_file(), self._tmp
        assert tmp is not None
        self._file = None
        committed = False
        try:
            if exc_type is None:
                self._check_complete()
            file.close()
            if exc_type is None:
                os.replace(tmp, self._path)
                committed = True
        finally:
            if not committed:
                file.close()
                tmp.unlink(missing_ok=True)

    def write_row(
        self,
        i: int,
        deflection_m: Any,
        *,
        force_n: Any = None,
        modal_m: Any = None,
        scalars: Mapping[str, float] | None = None,
        drive_phase_rad: float | None = None,
    ) -> None:
        """Write row ``i`` of a sweep or series (rows in any order; rewriting replaces).

        Parameters
        ----------
        i : int
            Row index, 0 <= i < n_points.
        deflection_m : array-like, shape (n,)
            Deflection of this row [m].
        force_n : array-like, shape (n,)
            True tip-sample force [N]; required exactly when the file has labels.
        modal_m : array-like, shape (n_modes, n)
            Modal deflections [m]; required exactly when n_modes > 0.
        scalars : dict of str to float, optional
            Per-row label scalars (e.g. ``dissipated_energy_j`` [J]); every row must name the
            same ones. Stored as datasets of shape (n_points,).
        drive_phase_rad : float, optional
            Drive phase at this row's first sample [rad] (design.md section 2), when it was not
            given to the constructor; then every row must give it. Stored as a dataset of shape
            (n_points,).
        """
        file = self._open_file()
        if self._n_points is None:
            raise ValueError("write_row needs a sweep (n_points given); use append instead")
        if isinstance(i, bool) or not isinstance(i, int | np.integer):
            raise ValueError(f"i must be an integer in [0, {self._n_points}), got {i!r}")
        if not 0 <= i < self._n_points:
            raise ValueError(f"i must be in [0, {self._n_points}), got {i}")
        n = self._n_samples
        deflection, force, modal = self._check_block(deflection_m, force_n, modal_m, n)
        values = self._check_row_scalars(scalars)
        phase = self._check_row_phase(drive_phase_rad)
        file[DEFLECTION][i] = deflection
        if phase is not None:
            file[DRIVE_PHASE][i] = phase
        if self._labelled:
            group = file[LABELS_GROUP]
            group["force_n"][i] = force
            if modal is not None:
                group["modal_m"][:, i] = modal
            for name, value in values.items():
                group[name][i] = value
        self._written[i] = True

    def append(self, deflection_m: Any, *, force_n: Any = None, modal_m: Any = None) -> None:
        """Append the next block of samples to a single (1-D) trace.

        Parameters
        ----------
        deflection_m : array-like, shape (k,)
            The next k samples of deflection [m]; at most n_samples in total.
        force_n : array-like, shape (k,)
            True tip-sample force [N]; required exactly when the file has labels.
        modal_m : array-like, shape (n_modes, k)
            Modal deflections [m]; required exactly when n_modes > 0.
        """
        file = self._open_file()
        if self._n_points is not None:
            raise ValueError("append needs a single trace (n_points=None); use write_row instead")
        if not self._deflection:
            raise ValueError("append: this writer has no deflection record (deflection=False)")
        deflection, force, modal = self._check_block(deflection_m, force_n, modal_m, None)
        start, stop = self._filled, self._filled + deflection.shape[0]
        if stop > self._n_samples:
            raise ValueError(
                f"deflection_m: {deflection.shape[0]} samples exceed n_samples={self._n_samples}"
                f" ({self._n_samples - start} remain)"
            )
        file[DEFLECTION][start:stop] = deflection
        if self._labelled:
            file[LABELS_GROUP]["force_n"][start:stop] = force
            if modal is not None:
                file[LABELS_GROUP]["modal_m"][:, start:stop] = modal
        self._filled = stop

    def _open_file(self) -> h5py.File:
        if self._file is None:
            raise RuntimeError("TraceWriter must be used inside its `with` block")
        return self._file

    def _create_layout(self, file: h5py.File) -> None:
        file.attrs["format"] = FORMAT
        file.attrs["format_version"] = np.int64(FORMAT_VERSION)
        for name, value in self._metadata.items():
            if value is None:
                continue
            if isinstance(value, np.ndarray) and name != "higher_mode_frequencies_hz":
                file.create_dataset(name, data=value)
            else:
                file.attrs[name] = value
        shape = self._shape
        chunks = (1, shape[1]) if len(shape) == 2 else (min(shape[0], _BLOCK),)
        if not self._deflection:
            return
        file.create_dataset(DEFLECTION, shape, "f8", chunks=chunks, fillvalue=np.nan)
        if not self._labelled:
            return
        group = file.create_group(LABELS_GROUP)
        group.attrs["model"] = json.dumps(self._model)
        group.attrs["effect"] = self._effect
        group.create_dataset("force_n", shape, "f8", chunks=chunks, fillvalue=np.nan)
        if self._n_modes:
            group.create_dataset(
                "modal_m",
                (self._n_modes, *shape),
                "f8",
                chunks=(self._n_modes, *chunks),
                fillvalue=np.nan,
            )
        for name, value in self._scalars.items():
            group.create_dataset(name, data=value)
        if self._extra:
            extra = group.create_group(EXTRA_GROUP)
            for name, value in self._extra.items():
                extra.create_dataset(name, data=value)

    def _check_block(
        self, deflection_m: Any, force_n: Any, modal_m: Any, length: int | None
    ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        shape = None if length is None else (length,)
        deflection = finite_array("deflection_m", deflection_m, ndim=(1,), shape=shape)
        k = deflection.shape[0]
        force = modal = None
        if self._labelled:
            if force_n is None:
                raise ValueError("force_n is required: this file has labels (model was given)")
            force = finite_array("force_n", force_n, ndim=(1,), shape=(k,))
        elif force_n is not None:
            raise ValueError("force_n given, but the file has no labels: pass model= as well")
        if self._n_modes:
            if modal_m is None:
                raise ValueError(f"modal_m is required: n_modes={self._n_modes}")
            modal = finite_array("modal_m", modal_m, ndim=(2,), shape=(self._n_modes, k))
        elif modal_m is not None:
            raise ValueError("modal_m given, but n_modes=0")
        return deflection, force, modal

    def _check_row_scalars(self, scalars: Mapping[str, float] | None) -> dict[str, float]:
        scalars = dict(scalars or {})
        if scalars and not self._labelled:
            raise ValueError("scalars given, but the file has no labels: pass model= as well")
        values = {
            check_name("scalars", name): finite_number(f"scalars[{name!r}]", value)
            for name, value in scalars.items()
        }
        names = tuple(sorted(values))
        if self._row_scalars is None:
            clash = sorted(set(names) & set(self._scalars))
            if clash:
                raise ValueError(f"scalars {clash} were already given to TraceWriter(scalars=)")
            for name in names:
                self._open_file()[LABELS_GROUP].create_dataset(
                    name, (self._n_points,), "f8", fillvalue=np.nan
                )
            self._row_scalars = names
        elif names != self._row_scalars:
            raise ValueError(
                f"scalars must name the same quantities in every row: {self._row_scalars}, "
                f"got {names}"
            )
        return values

    def _check_row_phase(self, drive_phase_rad: Any) -> float | None:
        given = drive_phase_rad is not None
        if given and self._metadata["drive_phase_rad"] is not None:
            raise ValueError(
                "drive_phase_rad was already given to TraceWriter(...); do not repeat it per row"
            )
        if self._row_phase != given and np.any(self._written):
            raise ValueError(
                "drive_phase_rad must be given for every row or for none "
                f"({'missing' if not given else 'unexpected'} in this row)"
            )
        if not given:
            return None
        value = finite_number("drive_phase_rad", drive_phase_rad)
        if not self._row_phase:
            self._open_file().create_dataset(DRIVE_PHASE, (self._n_points,), "f8",
                                             fillvalue=np.nan)
            self._row_phase = True
        return value

    def _check_complete(self) -> None:
        if not self._deflection:
            return
        if self._n_points is None:
            if self._filled != self._n_samples:
                raise ValueError(
                    f"only {self._filled} of n_samples={self._n_samples} samples were appended;"
                    f" nothing was written to {self._path}"
                )
            return
        missing = np.flatnonzero(~self._written)
        if missing.size:
            shown = ", ".join(str(i) for i in missing[:10]) + (", ..." if missing.size > 10 else "")
            raise ValueError(
                f"{missing.size} of n_points={self._n_points} rows were never written ({shown});"
                f" nothing was written to {self._path}"
            )


def write_trace(trace: Trace, path: str | os.PathLike[str]) -> Path:
    """Write ``trace`` (with its labels, if any) to ``path`` atomically.

    Parameters
    ----------
    trace : Trace
        The recording; a sweep or series is written one row per chunk so `read_rows` stays
        cheap.
    path : str or os.PathLike
        Target file (``.h5``); an existing file is replaced.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    labels = trace.labels
    label_args: dict[str, Any] = {}
    if labels is not None:
        label_args = {
            "n_modes": 0 if labels.modal_m is None else labels.modal_m.shape[0],
            "model": labels.model,
            "effect": labels.effect,
            "scalars": labels.scalars,
            "extra": labels.extra,
        }
    force = None if labels is None else labels.force_n
    modal = None if labels is None else labels.modal_m
    with TraceWriter(
        path,
        n_samples=trace.n_samples,
        n_points=trace.n_points if trace.has_rows else None,
        deflection=trace.deflection_m is not None,
        **label_args,
        **trace.metadata(),
    ) as writer:
        if trace.deflection_m is None:
            return Path(path)
        if not trace.has_rows:
            writer.append(trace.deflection_m, force_n=force, modal_m=modal)
            return Path(path)
        for i in range(trace.n_points):
            writer.write_row(
                i,
                trace.deflection_m[i],
                force_n=None if force is None else force[i],
                modal_m=None if modal is None else modal[:, i],
            )
    return Path(path)
