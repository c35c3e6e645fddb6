"""Reading trace files: `read_trace` loads one, `TraceReader` / `read_rows` stream a sweep.

Every reader validates the file against format version 1 and raises `TraceFormatError`
naming the file and the offending attribute or dataset. Labels are opened only on request:
with ``labels=False`` (the default) the ``/labels`` group is never touched.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType
from typing import Any, TypeVar, final

import h5py
import numpy as np

from afmlearn.io._format import (
    ATTR_OR_DATASET,
    DEFLECTION,
    EXTRA_GROUP,
    FORMAT,
    LABELS_ARRAYS,
    LABELS_GROUP,
    LOCKIN_AMPLITUDE,
    OPTIONAL_ATTR_OR_DATASET,
    OPTIONAL_DATASETS,
    REQUIRED_ATTRS,
    SUPPORTED_VERSIONS,
)
from afmlearn.io.errors import TraceFormatError
from afmlearn.io.labels import Labels
from afmlearn.io.trace import METADATA_FIELDS, Trace, check_metadata, row_index, row_metadata

__all__ = ["TraceReader", "read_rows", "read_trace"]

T = TypeVar("T")


def read_trace(path: str | os.PathLike[str], *, labels: bool = False) -> Trace:
    """Load and validate a whole trace file.

    Parameters
    ----------
    path : str or os.PathLike
        A trace file (format version 1).
    labels : bool, default False
        Also read the ``/labels`` group (None when the file has none). Analysis code under
        test must leave this False; the group is then never opened.

    Returns
    -------
    Trace
        ``deflection_m`` has shape (n,) or, for a sweep, (n_points, n).

    Raises
    ------
    TraceFormatError
        If the file is missing, not HDF5, or breaks the format.
    afmlearn.io.instruments.RecordingError
        For an instrument file (``.ibw``, ``.jpk-force``, ``.csv``, ``.npz`` ...), which is
        handed to `afmlearn.io.instruments.open_trace` (calibration from the file only).
    """
    path = Path(path)
    from afmlearn.io.instruments import is_instrument_file, open_trace  # lazy: no cycle

    if is_instrument_file(path):
        return open_trace(path)
    with _open(path) as file:
        deflection, shape, metadata = _read_header(file, path)
        truth = None
        if labels and (group := _labels_group(file, path, shape)) is not None:
            truth = _read_labels(group, path, row=None)
        values = None if deflection is None else deflection[()]
        return _checked(path, Trace, values, labels=truth, **metadata)


@final
class TraceReader:
    """Read a trace file one row at a time (a sweep is never loaded whole).

    Opening validates the metadata and the shapes of all datasets; each row's values are
    validated when read. Use as a context manager (or call `close`).

    Parameters
    ----------
    path : str or os.PathLike
        A trace file (format version 1).
    labels : bool, default False
        Attach each row's labels; with False the ``/labels`` group is never opened.

    Examples
    --------
    >>> with TraceReader("sweep.h5") as reader:            # doctest: +SKIP
    ...     amplitudes = [np.ptp(row.deflection_m) / 2 for row in reader]
    """

    def __init__(self, path: str | os.PathLike[str], *, labels: bool = False) -> None:
        self._path = Path(path)
        self._file = _open(self._path)
        try:
            self._deflection, self._shape, self._metadata = _read_header(self._file, self._path)
            self._labels = (
                _labels_group(self._file, self._path, self._shape) if labels else None
            )
        except BaseException:
            self._file.close()
            raise

    @property
    def path(self) -> Path:
        """The file being read."""
        return self._path

    @property
    def shape(self) -> tuple[int, ...]:
        """Shape of ``deflection_m``: (n,) or (n_points, n) (of ``amplitude_m`` for curves)."""
        return self._shape

    @property
    def has_rows(self) -> bool:
        """True when ``deflection_m`` is 2-D (a sweep or a set-point series)."""
        return len(self.shape) == 2

    @property
    def is_sweep(self) -> bool:
        """True when the file holds a sweep (2-D, one drive frequency per row)."""
        return self.has_rows and np.ndim(self._metadata["drive_frequency_hz"]) == 1

    @property
    def is_series(self) -> bool:
        """True when the file holds a set-point series (2-D, one rest gap per row)."""
        return self.has_rows and np.shape(self._metadata["gap_m"]) == (self.shape[0],)

    @property
    def n_points(self) -> int:
        """Number of rows; 1 for a single trace."""
        return self.shape[0] if self.has_rows else 1

    @property
    def n_samples(self) -> int:
        """Samples per row n."""
        return self.shape[-1]

    @property
    def metadata(self) -> dict[str, Any]:
        """Validated metadata: the keyword fields of `Trace` besides the arrays it streams."""
        return dict(self._metadata)

    def __len__(self) -> int:
        return self.n_points

    def __iter__(self) -> Iterator[Trace]:
        for i in range(self.n_points):
            yield self.row(i)

    def row(self, i: int) -> Trace:
        """Row ``i`` as a single trace (for a single-trace file, row 0 is the whole trace).

        Parameters
        ----------
        i : int
            Row index, 0 <= i < n_points.

        Returns
        -------
        Trace
            ``deflection_m`` of shape (n,); ``drive_frequency_hz`` [Hz], ``gap_m`` [m] and
            ``drive_phase_rad`` [rad] of that row; the row's labels if requested (array
            scalars reduced to that row's value).
        """
        checked = row_index(i, self.n_points)
        index = checked if self.has_rows else None
        metadata = dict(self._metadata)
        if index is not None:
            metadata = row_metadata(metadata, index, self.n_points)
        truth = None
        if self._labels is not None:
            truth = _read_labels(self._labels, self._path, row=index)
        if self._deflection is None:
            deflection = None
        else:
            deflection = self._deflection[()] if index is None else self._deflection[index]
        return _checked(self._path, Trace, deflection, labels=truth, **metadata)

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def __enter__(self) -> TraceReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def read_rows(path: str | os.PathLike[str], *, labels: bool = False) -> Iterator[Trace]:
    """Yield the rows of a trace file one at a time (see `TraceReader.row`).

    Parameters
    ----------
    path : str or os.PathLike
        A trace file; a single-trace file yields one trace.
    labels : bool, default False
        Attach each row's labels.

    Yields
    ------
    Trace
        One row, ``deflection_m`` of shape (n,).
    """
    with TraceReader(path, labels=labels) as reader:
        yield from reader


def _checked(path: Path, build: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """Call ``build``; turn its ``ValueError`` into a `TraceFormatError` naming ``path``."""
    try:
        return build(*args, **kwargs)
    except TraceFormatError:
        raise
    except ValueError as err:
        raise TraceFormatError(f"{path}: {err}") from err


def _found(value: Any) -> str:
    if isinstance(value, np.generic):
        value = value.item()
    return "it is missing" if value is None else f"found {value!r}"


def _decode(value: Any) -> Any:
    return value.decode("utf-8") if isinstance(value, bytes) else value


def _open(path: Path) -> h5py.File:
    if not path.is_file():
        raise TraceFormatError(f"{path}: no such file")
    try:
        return h5py.File(path, "r")
    except OSError as err:
        raise TraceFormatError(f"{path}: not a readable HDF5 file ({err})") from err


def _read_header(
    file: h5py.File, path: Path
) -> tuple[h5py.Dataset | None, tuple[int, ...], dict[str, Any]]:
    """Check format, version and structure.

    Returns ``deflection_m`` (unread; None for lock-in curves without it), its shape (that of
    ``amplitude_m`` when it is absent) and the validated metadata.
    """
    fmt = _decode(file.attrs.get("format"))
    if fmt != FORMAT:
        raise TraceFormatError(f"{path}: attribute 'format' must be {FORMAT!r}, {_found(fmt)}")
    version = file.attrs.get("format_version")
    if (
        isinstance(version, bool | np.bool_)
        or not isinstance(version, int | np.integer)
        or int(version) not in SUPPORTED_VERSIONS
    ):
        raise TraceFormatError(
            f"{path}: attribute 'format_version' must be one of {SUPPORTED_VERSIONS}, "
            f"{_found(version)}"
        )
    deflection = file.get(DEFLECTION) if DEFLECTION in file else None
    if deflection is None and isinstance(file.get(LOCKIN_AMPLITUDE), h5py.Dataset):
        shape: tuple[int, ...] = file[LOCKIN_AMPLITUDE].shape
        if len(shape) != 1:
            raise TraceFormatError(
                f"{path}: dataset {LOCKIN_AMPLITUDE!r} must have shape (n,), found {shape}"
            )
    elif not isinstance(deflection, h5py.Dataset):
        raise TraceFormatError(
            f"{path}: missing required dataset {DEFLECTION!r} (optional only for lock-in "
            f"curves with a dataset {LOCKIN_AMPLITUDE!r})"
        )
    elif (
        deflection.ndim not in (1, 2) or deflection.dtype.kind not in "iuf" or deflection.size == 0
    ):
        raise TraceFormatError(
            f"{path}: dataset {DEFLECTION!r} must be a non-empty real array of shape (n,) or "
            f"(n_points, n), found shape {deflection.shape} of dtype {deflection.dtype}"
        )
    else:
        shape = deflection.shape
    values: dict[str, Any] = {}
    datasets = (*ATTR_OR_DATASET, *OPTIONAL_ATTR_OR_DATASET, *OPTIONAL_DATASETS)
    for name in METADATA_FIELDS:
        in_attrs = name in file.attrs
        in_data = name in datasets and name in file
        if in_attrs and in_data:
            raise TraceFormatError(f"{path}: {name!r} must be an attribute or a dataset, not both")
        if in_data:
            item = file[name]
            if not isinstance(item, h5py.Dataset):
                raise TraceFormatError(f"{path}: {name!r} must be a dataset, found a group")
            values[name] = item[()]
        elif in_attrs:
            values[name] = _decode(file.attrs[name])
        elif name in REQUIRED_ATTRS:
            raise TraceFormatError(f"{path}: missing required attribute {name!r}")
        elif name in ATTR_OR_DATASET:
            raise TraceFormatError(f"{path}: missing required attribute or dataset {name!r}")
    metadata = _checked(
        path,
        check_metadata,
        n_points=shape[0] if len(shape) == 2 else None,
        n_samples=shape[-1],
        **values,
    )
    return deflection, shape, metadata


def _labels_group(file: h5py.File, path: Path, shape: tuple[int, ...]) -> h5py.Group | None:
    """Open ``/labels`` (None if absent) and check the shapes of its datasets."""
    if LABELS_GROUP not in file:
        return None
    try:
        group = file[LABELS_GROUP]
    except (KeyError, OSError) as err:
        raise TraceFormatError(f"{path}: group {LABELS_GROUP!r} cannot be opened ({err})") from err
    if not isinstance(group, h5py.Group):
        raise TraceFormatError(f"{path}: {LABELS_GROUP!r} must be a group, found a dataset")
    expected = {"force_n": shape, "modal_m": ("n_modes", *shape)}
    for name, item in group.items():
        where = f"{path}: '{LABELS_GROUP}/{name}'"
        if name == EXTRA_GROUP:
            if not isinstance(item, h5py.Group) or not all(
                isinstance(sub, h5py.Dataset) for sub in item.values()
            ):
                raise TraceFormatError(f"{where} must be a group of datasets")
            continue
        if not isinstance(item, h5py.Dataset):
            raise TraceFormatError(f"{where} must be a dataset, found a group")
        if name in LABELS_ARRAYS:
            found = item.shape if name == "force_n" else item.shape[1:]
            if found != shape:
                raise TraceFormatError(
                    f"{where} must have shape {expected[name]}, found {item.shape}"
                )
        elif item.ndim != 0 and not (len(shape) == 2 and item.shape == shape[:1]):
            raise TraceFormatError(
                f"{where}: a scalar must be 0-d or, for a sweep, of shape (n_points,) = "
                f"{shape[:1]}; found shape {item.shape}"
            )
    if "force_n" not in group:
        raise TraceFormatError(f"{path}: missing required dataset '{LABELS_GROUP}/force_n'")
    return group


def _read_labels(group: h5py.Group, path: Path, *, row: int | None) -> Labels:
    """Read the labels (``row`` of a sweep, or everything when ``row`` is None)."""
    take = (lambda item: item[()]) if row is None else (lambda item: item[row])
    model_text = _decode(group.attrs.get("model", "{}"))
    try:
        model = json.loads(model_text)
    except (TypeError, json.JSONDecodeError) as err:
        raise TraceFormatError(
            f"{path}: attribute '{LABELS_GROUP}/model' must be a JSON string, "
            f"found {model_text!r:.80}"
        ) from err
    scalars: dict[str, Any] = {}
    for name, item in group.items():
        if name in (*LABELS_ARRAYS, EXTRA_GROUP):
            continue
        if item.dtype.kind in "OSU":
            scalars[name] = item.asstr()[()]
        else:
            scalars[name] = item[()] if item.ndim == 0 else take(item)
    extra = group.get(EXTRA_GROUP)
    modal = group.get("modal_m")
    return _checked(
        path,
        Labels,
        take(group["force_n"]),
        modal_m=None if modal is None else (modal[()] if row is None else modal[:, row]),
        model=model,
        effect=_decode(group.attrs.get("effect", "none")),
        scalars=scalars,
        extra={} if extra is None else {name: item[()] for name, item in extra.items()},
    )
