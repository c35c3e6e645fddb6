"""Ground truth stored with simulated traces (never read by analysis code under test)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, final

import numpy as np

from afmlearn.io._checks import FloatArray, finite_array, finite_number, text
from afmlearn.io._format import EXTRA_GROUP, LABELS_ARRAYS

__all__ = ["Labels"]

Scalar = float | str | FloatArray


@final
@dataclass(frozen=True, eq=False)
class Labels:
    """The truth behind one simulated trace.

    Parameters
    ----------
    force_n : array-like, shape (n,) or (n_points, n)
        True tip-sample force [N], same shape as the trace's ``deflection_m``.
    modal_m : array-like, shape (n_modes, n) or (n_modes, n_points, n), optional
        Modal deflections [m]; their sum is the noise-free deflection.
    model : dict, optional
        Model name and all parameters; must be JSON-serialisable (it is stored as a JSON
        string and normalised through JSON here, so a round trip returns an equal dict).
    effect : str, default "none"
        The effect injected into the simulation (see design.md section 3).
    scalars : dict of str to float, str or array of shape (n_points,), optional
        Per-trace numbers such as ``dissipated_energy_j`` [J], ``contact_fraction`` [-] or
        ``coupling_strength`` [-]; arrays give one value per row of a sweep.
    extra : dict of str to array, optional
        Further arrays of any shape, e.g. the gap of an approach ramp [m].
    """

    force_n: FloatArray
    _: KW_ONLY
    modal_m: FloatArray | None = None
    model: dict[str, Any] = field(default_factory=dict)
    effect: str = "none"
    scalars: dict[str, Scalar] = field(default_factory=dict)
    extra: dict[str, FloatArray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "force_n", finite_array("labels.force_n", self.force_n, ndim=(1, 2)))
        if self.modal_m is not None:
            set_(self, "modal_m", finite_array("labels.modal_m", self.modal_m, ndim=(2, 3)))
        set_(self, "model", check_model(self.model))
        set_(self, "effect", check_effect(self.effect))
        set_(self, "scalars", check_scalars(self.scalars))
        set_(self, "extra", check_extra(self.extra))

    def check_shape(self, shape: tuple[int, ...]) -> None:
        """Raise ``ValueError`` unless the labels fit a deflection of shape ``shape``.

        Parameters
        ----------
        shape : tuple of int
            ``(n,)`` for a single trace or ``(n_points, n)`` for a sweep.
        """
        if self.force_n.shape != shape:
            raise ValueError(
                f"labels.force_n must have the shape of deflection_m {shape}, "
                f"got {self.force_n.shape}"
            )
        if self.modal_m is not None and self.modal_m.shape[1:] != shape:
            raise ValueError(
                f"labels.modal_m must have shape (n_modes, *{shape}), got {self.modal_m.shape}"
            )
        check_scalar_shapes(self.scalars, shape)

    def row(self, i: int) -> Labels:
        """The labels of row ``i`` of a 2-D trace (per-row scalars reduced to their value).

        Parameters
        ----------
        i : int
            Row index, 0 <= i < n_points (the caller checks the range).

        Returns
        -------
        Labels
            ``force_n`` (n,), ``modal_m`` (n_modes, n); ``extra`` is shared unchanged.
        """
        if self.force_n.ndim != 2:
            raise ValueError("labels.row needs the labels of a 2-D trace (one row per point)")
        return Labels(
            self.force_n[i],
            modal_m=None if self.modal_m is None else self.modal_m[:, i],
            model=self.model,
            effect=self.effect,
            scalars={
                name: float(value[i]) if isinstance(value, np.ndarray) else value
                for name, value in self.scalars.items()
            },
            extra=self.extra,
        )


def check_model(model: Any) -> dict[str, Any]:
    """Return ``model`` normalised through JSON; raise ``ValueError`` if it cannot be."""
    if not isinstance(model, Mapping):
        raise ValueError(f"labels.model must be a dict, got {type(model).__name__}")
    try:
        return json.loads(json.dumps(dict(model), allow_nan=False))
    except (TypeError, ValueError) as err:
        raise ValueError(
            f"labels.model must be JSON-serialisable with finite numbers: {err}"
        ) from err


def check_effect(effect: Any) -> str:
    """Return ``effect`` as a non-empty str."""
    effect = text("labels.effect", effect)
    if not effect:
        raise ValueError("labels.effect must be a non-empty string")
    return effect


def check_name(kind: str, name: Any) -> str:
    """Return ``name`` if it can name an HDF5 dataset next to the fixed label entries."""
    reserved = (*LABELS_ARRAYS, EXTRA_GROUP)
    if not isinstance(name, str) or not name or "/" in name or name in (".", *reserved):
        raise ValueError(
            f"labels.{kind} names must be non-empty strings without '/' and not one of "
            f"{reserved}, got {name!r}"
        )
    return name


def check_scalars(scalars: Any) -> dict[str, Scalar]:
    """Return a checked copy of ``scalars`` (floats, strings or 1-D finite arrays)."""
    if not isinstance(scalars, Mapping):
        raise ValueError(f"labels.scalars must be a dict, got {type(scalars).__name__}")
    checked: dict[str, Scalar] = {}
    for name, value in scalars.items():
        key = f"labels.scalars[{check_name('scalars', name)!r}]"
        if isinstance(value, str | bytes):
            checked[name] = text(key, value)
        elif np.ndim(value) == 0:
            checked[name] = finite_number(key, value)
        else:
            checked[name] = finite_array(key, value, ndim=(1,))
    return checked


def check_scalar_shapes(scalars: Mapping[str, Scalar], shape: tuple[int, ...]) -> None:
    """Raise ``ValueError`` unless array scalars have shape (n_points,) of a sweep ``shape``."""
    for name, value in scalars.items():
        if isinstance(value, np.ndarray) and (len(shape) != 2 or value.shape != shape[:1]):
            raise ValueError(
                f"labels.scalars[{name!r}]: arrays are allowed only for sweeps and must "
                f"have shape (n_points,) = {shape[:1]}, got {value.shape}"
            )


def check_extra(extra: Any) -> dict[str, FloatArray]:
    """Return a checked copy of ``extra`` (finite real arrays of any shape)."""
    if not isinstance(extra, Mapping):
        raise ValueError(f"labels.extra must be a dict, got {type(extra).__name__}")
    return {
        check_name("extra", name): finite_array(f"labels.extra[{name!r}]", value, ndim=None)
        for name, value in extra.items()
    }
