"""Validation helpers shared by the trace records and the writer (private)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def real_number(name: str, value: Any) -> float:
    """Return ``value`` as a float; raise ``ValueError`` if it is not one real number."""
    arr = np.asarray(value)
    if arr.ndim != 0 or arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be a real number, got {value!r}")
    return float(arr)


def finite_number(name: str, value: Any) -> float:
    """Return ``value`` as a float; it must be a finite real number."""
    x = real_number(name, value)
    if not np.isfinite(x):
        raise ValueError(f"{name} must be a finite number, got {x!r}")
    return x


def positive(name: str, value: Any) -> float:
    """Return ``value`` as a float; it must be a finite real number > 0."""
    x = real_number(name, value)
    if not (np.isfinite(x) and x > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {x!r}")
    return x


def optional_positive(name: str, value: Any) -> float | None:
    """Like :func:`positive`, but ``None`` passes through."""
    return None if value is None else positive(name, value)


def text(name: str, value: Any) -> str:
    """Return ``value`` as a str (bytes are decoded as UTF-8)."""
    if isinstance(value, bytes):
        value = value.decode("utf-8")
    if not isinstance(value, str):
        raise ValueError(f"{name} must be a string, got {value!r}")
    return value


def finite_array(
    name: str,
    value: Any,
    *,
    ndim: tuple[int, ...] | None,
    shape: tuple[int, ...] | None = None,
    positive: bool = False,
) -> FloatArray:
    """Return ``value`` as a read-only float64 array after checking it.

    Parameters
    ----------
    name : str
        Name used in error messages.
    value : array-like
        The values.
    ndim : tuple of int or None
        Allowed numbers of dimensions (None: any).
    shape : tuple of int, optional
        Required shape.
    positive : bool, default False
        Require every element to be > 0.

    Returns
    -------
    ndarray of float64
        A read-only view (no copy when ``value`` already is a float64 array).
    """
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if ndim is not None and arr.ndim not in ndim:
        dims = " or ".join(str(d) for d in ndim)
        raise ValueError(f"{name} must have {dims} dimension(s), got shape {arr.shape}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    arr = arr.astype(np.float64, copy=False)
    n_bad = int(np.count_nonzero(~np.isfinite(arr)))
    if n_bad:
        raise ValueError(f"{name} must be finite, found {n_bad} NaN/inf value(s)")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} must be > 0 everywhere, found min {arr.min()!r}")
    view = arr.view()
    view.flags.writeable = False
    return view


def segment_array(name: str, value: Any, n_samples: int) -> NDArray[np.int8]:
    """Return ``value`` as a read-only int8 array of shape (n_samples,) holding only 0 and 1."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iub" and not (
        arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr))
    ):
        raise ValueError(f"{name} must hold integers 0 (approach) or 1 (retraction), "
                         f"got dtype {arr.dtype}")
    if arr.shape != (n_samples,):
        raise ValueError(f"{name} must have shape (n,) = ({n_samples},), got shape {arr.shape}")
    if not np.all((arr == 0) | (arr == 1)):
        raise ValueError(f"{name} must hold only 0 (approach) and 1 (retraction), "
                         f"found {sorted(set(np.unique(arr).tolist()) - {0, 1})[:5]}")
    out = arr.astype(np.int8)
    out.flags.writeable = False
    return out


def count(name: str, value: Any, *, minimum: int) -> int:
    """Return ``value`` as an int >= ``minimum`` (bools are rejected)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)
