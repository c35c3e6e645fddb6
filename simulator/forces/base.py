"""Abstract tip--sample force model and the sum of models.

A force model is a small immutable object with dimensionless parameters (lengths in units of
the rest gap ``L_ref``, forces in units of ``k L_ref``, rates per ``tau = omega0 t``). It has

* :meth:`AbstractForceModel.law`, its terms in the one force-law representation
  (:class:`~simulator.forces.law.ForceLaw`) that the compiled kernels read, and
* a plain NumPy reference evaluation ``model(z, zdot, contact)`` written term by term from the
  physics (used by tests and by analysis code). Tests check one against the other.

Everything else (``a0``, the break indentation, whether the model has a contact branch or can
dissipate) is read from the law, never overridden per model.

Sign convention (``physics.md`` section 1): ``F > 0`` is repulsive (pushes the tip towards
larger ``z``); dissipative terms oppose ``z_dot``.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from typing import Any, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .law import ForceLaw

__all__ = ["AbstractForceModel", "ForceSum", "check_range"]


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

    Subclasses store validated parameters in ``__init__`` and implement three abstract
    methods: :meth:`law` (the terms, for the compiled kernels), :meth:`_reference` (the NumPy
    physics, for tests and analysis) and :meth:`parameters` (for labels). Models are added with
    ``+`` (:class:`ForceSum`).
    """

    #: short name used in configs and labels
    name: str = "abstract"
    #: long-range terms that stop growing once the tip touches (evaluated at ``a0`` in contact)
    saturates_in_contact: bool = False
    #: False for laws whose long-range terms must not be held at ``a0`` by a contact law
    combines_with_contact: bool = True

    # ------------------------------------------------------------------ abstract hooks
    @abc.abstractmethod
    def law(self) -> ForceLaw:
        """This model as a :class:`~simulator.forces.law.ForceLaw` (the kernels' input)."""

    @abc.abstractmethod
    def _reference(
        self, z: NDArray[np.float64], zdot: NDArray[np.float64], contact: NDArray[np.bool_]
    ) -> NDArray[np.float64]:
        """Plain NumPy force for gap ``z``, rate ``zdot`` and regime ``contact`` (same shape)."""

    @abc.abstractmethod
    def parameters(self) -> dict[str, Any]:
        """All parameters as a JSON-serialisable mapping (used for labels)."""

    # ------------------------------------------------------------------ read from the law
    @property
    def a0(self) -> float:
        """Contact onset ``a0`` (dimensionless); ``0`` for models without contact."""
        return self.law().a0

    @property
    def break_indentation(self) -> float:
        """Indentation (<= 0) at which an established contact breaks; 0 if not hysteretic."""
        return -self.law().break_distance

    @property
    def has_contact(self) -> bool:
        """True when the model has a contact branch (a regime switched at ``z = a0``)."""
        return self.law().has_contact

    @property
    def dissipative(self) -> bool:
        """True if the model can dissipate energy over a closed orbit."""
        return self.law().dissipative

    def contact_state(self, z: ArrayLike) -> NDArray[np.bool_]:
        """Regime of a tip arriving from far away at gap ``z`` (the approach branch)."""
        z = np.asarray(z, dtype=float)
        if not self.has_contact:
            return np.zeros(z.shape, dtype=bool)
        return z <= self.a0

    def __call__(
        self, z: ArrayLike, zdot: ArrayLike = 0.0, contact: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Evaluate the force for a whole batch (NumPy reference).

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

    def __add__(self, other: AbstractForceModel) -> ForceSum:
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


@final
class ForceSum(AbstractForceModel):
    """Sum of force models sharing one regime state (``DMT(...) + Electrostatic(...)``).

    At most one member may carry a contact law; long-range and damping terms add. The sum's
    law is the concatenation of its members' terms. A model with
    ``combines_with_contact = False`` (:class:`~simulator.forces.LennardJones`: its ``z**-2``
    attraction acts at every gap) cannot be combined with a contact law, which would hold its
    long-range terms at ``a0`` in contact.

    Parameters
    ----------
    terms : sequence of AbstractForceModel
        At least one model. Nested sums are flattened.
    """

    def __init__(self, terms: Sequence[AbstractForceModel]) -> None:
        flat: list[AbstractForceModel] = []
        for t in terms:
            if not isinstance(t, AbstractForceModel):
                raise ValueError(f"terms: expected force models, got {type(t).__name__}")
            flat.extend(t.terms if isinstance(t, ForceSum) else [t])
        if not flat:
            raise ValueError("terms: need at least one force model")
        self.terms = tuple(flat)
        law = self.law()  # validates compatibility (one contact law)
        if law.has_contact and not all(t.combines_with_contact for t in flat):
            raise ValueError("terms: LennardJones cannot be combined with a contact law (its "
                             "z**-2 attraction would be frozen at a0 in contact)")

    @property
    def name(self) -> str:  # type: ignore[override]
        return "+".join(t.name for t in self.terms)

    def law(self) -> ForceLaw:
        out = self.terms[0].law()
        for t in self.terms[1:]:
            out = out + t.law()
        return out

    def _reference(self, z: np.ndarray, zdot: np.ndarray, contact: np.ndarray) -> np.ndarray:
        z_held = np.where(contact, self.a0, z)  # long-range terms saturate at contact
        return sum((t._reference(z_held if t.saturates_in_contact else z, zdot, contact)
                    for t in self.terms), np.zeros_like(z))

    def parameters(self) -> dict[str, Any]:
        return {"terms": [t.to_dict() for t in self.terms]}


def _same(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    return repr(a) == repr(b)


def clipped_pow(d: NDArray[np.float64], p: float) -> NDArray[np.float64]:
    """``max(d, 0) ** p`` (NumPy reference of a one-sided power law)."""
    return np.maximum(d, 0.0) ** p
