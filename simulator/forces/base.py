"""Abstract tip--sample force model.

A force model is a small immutable object with dimensionless parameters (lengths in units of
the rest gap ``L_ref``, forces in units of ``k L_ref``, rates per ``tau = omega0 t``). It has

* a plain NumPy reference evaluation ``model(z, zdot, contact)`` written term by term from the
  physics (used by tests and by analysis code), and
* ``coefficients()``, the canonical vector read by the compiled kernel in ``_kernel.py`` (the
  fast path used by the integrators). Tests check one against the other.

Sign convention (``physics.md`` §1): ``F > 0`` is repulsive (pushes the tip towards larger
``z``); dissipative terms oppose ``z_dot``.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _layout as L

__all__ = ["AbstractForceModel", "check_range"]


def check_range(
    name: str,
    value: float,
    *,
    low: float = -math.inf,
    high: float = math.inf,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``float(value)`` or raise ``ValueError`` naming ``name`` and the allowed range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    lo_ok = v > low if low_open else v >= low
    hi_ok = v < high if high_open else v <= high
    if not math.isfinite(v) or not lo_ok or not hi_ok:
        lb = "(" if low_open else "["
        hb = ")" if high_open else "]"
        raise ValueError(f"{name} must lie in {lb}{low:g}, {high:g}{hb}, got {value!r}")
    return v


class AbstractForceModel(abc.ABC):
    """Base class of tip--sample force models (dimensionless).

    Subclasses store validated parameters in ``__init__`` and implement the single abstract
    hook :meth:`_fill`, which writes their terms into the canonical coefficient vector.
    Reference evaluation is provided by :meth:`_reference`, also per subclass.
    """

    #: short name used in configs and labels
    name: str = "abstract"
    #: long-range terms that stop growing once the tip touches (evaluated at ``a0`` in contact)
    saturates_in_contact: bool = False

    # ------------------------------------------------------------------ abstract hooks
    @abc.abstractmethod
    def _fill(self, c: NDArray[np.float64]) -> None:
        """Write this model's terms into the canonical vector ``c`` (shape (N_COEFFICIENTS,))."""

    @abc.abstractmethod
    def _reference(
        self, z: NDArray[np.float64], zdot: NDArray[np.float64], contact: NDArray[np.bool_]
    ) -> NDArray[np.float64]:
        """Plain NumPy force for gap ``z``, rate ``zdot`` and regime ``contact`` (same shape)."""

    @abc.abstractmethod
    def parameters(self) -> dict[str, Any]:
        """All parameters as a JSON-serialisable mapping (used for labels)."""

    # ------------------------------------------------------------------ public API
    @property
    def a0(self) -> float:
        """Contact onset ``a0`` (dimensionless); ``0`` for models without contact."""
        return 0.0

    @property
    def break_indentation(self) -> float:
        """Indentation (<= 0) at which an established contact breaks; 0 if not hysteretic."""
        return 0.0

    @property
    def has_contact(self) -> bool:
        """True when the model has a contact branch (a regime switched at ``z = a0``)."""
        return bool(self.coefficients()[L.CONTACT])

    @property
    def dissipative(self) -> bool:
        """True if the model can dissipate energy over a closed orbit."""
        c = self.coefficients()
        return bool(c[L.VISCO] != 0.0 or c[L.EXPD] != 0.0 or c[L.JKR] != 0.0)

    def coefficients(self) -> NDArray[np.float64]:
        """Canonical coefficient vector, shape (N_COEFFICIENTS,), for the compiled kernel."""
        c = np.zeros(L.N_COEFFICIENTS)
        self._fill(c)
        return c

    def contact_state(self, z: ArrayLike) -> NDArray[np.bool_]:
        """Regime of a tip arriving from far away at gap ``z`` (the approach branch)."""
        z = np.asarray(z, dtype=float)
        if not self.has_contact:
            return np.zeros(z.shape, dtype=bool)
        return z <= self.a0

    def __call__(
        self, z: ArrayLike, zdot: ArrayLike = 0.0, contact: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Evaluate the force for a whole batch.

        Parameters
        ----------
        z : array-like, shape (...)
            Gap (dimensionless, > 0 where long-range terms are present).
        zdot : array-like, broadcastable to ``z``
            Gap rate ``dz/dtau`` (dimensionless).
        contact : array-like of bool, broadcastable to ``z``, optional
            Regime (history state). Defaults to the approach branch ``z <= a0``; hysteretic
            models need the true history to be passed.

        Returns
        -------
        ndarray, shape of ``z``
            Tip--sample force in units of ``k L_ref``, positive = repulsive.
        """
        z = np.asarray(z, dtype=float)
        zdot = np.broadcast_to(np.asarray(zdot, dtype=float), z.shape)
        if contact is None:
            contact = self.contact_state(z)
        contact = np.broadcast_to(np.asarray(contact, dtype=bool), z.shape)
        return self._reference(z, zdot, contact)

    def __add__(self, other: AbstractForceModel) -> AbstractForceModel:
        from .sum import ForceSum

        if not isinstance(other, AbstractForceModel):
            return NotImplemented
        return ForceSum([self, other])

    def to_dict(self) -> dict[str, Any]:
        """``{"model": name, "parameters": {...}}`` for labels."""
        return {"model": self.name, "parameters": dict(self.parameters())}

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.parameters().items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and _same(self.parameters(), other.parameters())

    def __hash__(self) -> int:
        return hash((type(self).__name__, repr(self.parameters())))


def _same(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    return repr(a) == repr(b)


def clipped_pow(d: NDArray[np.float64], p: float) -> NDArray[np.float64]:
    """``max(d, 0) ** p`` (NumPy reference of a one-sided power law)."""
    return np.maximum(d, 0.0) ** p
