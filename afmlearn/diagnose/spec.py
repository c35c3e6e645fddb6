"""`ModelSpec`: the structure of a candidate model -- the baseline plus a tuple of extensions.

Everything is dimensionless (lengths / ``L_ref``, time ``tau = omega0 t``, forces / ``k L_ref``).
The baseline is one lever mode (``K``, ``D``, drive ``B cos(Omega tau - phi)``) and the force
``F_ts = c_vdw z^-2 + c_contact delta^p`` (``z^-2`` held at ``a0`` in contact, ``delta = a0 -
z`` in contact, ``p = contact_exponent``; ``F_ts > 0`` repulsive). A cause of design.md
section 3 extends it by one *extension* object, a frozen final dataclass declared next to its
hypothesis (:mod:`afmlearn.diagnose.hypotheses`). An extension plays one of the four roles the
one compiled kernel (:func:`simulator.integrate._kernel.integrate_one` on a
:class:`simulator.forces.ForceLaw`) can integrate, each a base class here with one abstract
hook:

- :class:`AbstractForceTerm`, hook ``term()``: one more history-free force column, a library
  term (its values, sign constraint, name and kernel encoding);
- :class:`AbstractNeck`, hook ``contact_constants()``: the kernel's one history-dependent
  law -- the simulator's hysteretic JKR contact (:class:`simulator.forces.HystereticJKR`):
  attached from contact (``z <= a0``) until the neck breaks at its stability limit
  ``z = a0 + d_c``, one column ``alpha (a^3 - 1.5 r_j c_j a^1.5 + ..)`` (``alpha >= 0``); its
  state is the attachment along the orbit;
- :class:`AbstractExtraMode`, hook ``mode_parameters()``: a second lever mode sharing the tip
  force and drive (``f2/f0``, ``Q2``, gain ``g2``);
- :class:`AbstractOutputMap`, hook ``polynomial()``: the detector, measured
  ``y = x + b_2 x^2 + b_3 x^3 + ..`` of the true deflection ``x``.

Every extension also fills :meth:`AbstractExtension.report` (its parameters, SI where they have
units) and names its :attr:`~AbstractExtension.key`. The roles are the kernel's capabilities:
any number of force terms, at most one neck, one extra mode and one output map (a second
history law or a third mode would need the kernel extended first).

A spec's extensions are kept in one canonical order, whatever order they were added in: by
role (force terms, neck, extra mode, output map), force terms by :data:`FORCE_TERM_ORDER` (the
historical column order of the shipped causes), any other force term after those by its key.
So two specs with the same extensions are equal (``==``, hash) and have the same coefficient
layout: baseline terms, force terms, then the neck.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.identify.library import AFMLibrary, Indentation, InversePower, TermInput
from afmlearn.identify.library.base import AbstractTerm
from simulator import Scales
from simulator.forces.law import Kind

from ._kernel import invert_polynomial as _compiled_invert
from ._kernel import jkr_radius_sqrt
from ._kernel import neck_state as _compiled_neck_state

__all__ = ["ModelSpec", "FORCE_TERM_ORDER", "AbstractExtension", "AbstractForceTerm",
           "AbstractNeck", "AbstractExtraMode", "AbstractOutputMap", "neck_state",
           "invert_polynomial"]

FloatArray = NDArray[np.float64]
E = TypeVar("E", bound="AbstractExtension")

#: Keys of the shipped force terms in their canonical column order (the order before extensions
#: were objects: viscoelastic, long-range damping, electrostatic); a new force term goes after
#: these, ordered by its key, with no change here.
FORCE_TERM_ORDER: tuple[str, ...] = ("visco", "damping", "electrostatic")


class AbstractExtension(abc.ABC):
    """One cause's change of the baseline model (subclass one of the four roles below).

    Concrete extensions are frozen, final dataclasses (hashable: a spec is a cache key)
    declared in the cause's own ``hypotheses/<cause>.py``.
    """

    #: stable name of the feature (coefficient layout of nested models, warm starts); unique
    key: ClassVar[str] = ""
    #: position of the role in a spec (force terms, neck, extra mode, output map)
    _rank: ClassVar[int] = 0

    @abc.abstractmethod
    def report(self, scales: Scales) -> dict[str, Any]:
        """The extension's parameters for :meth:`DiagnosisModel.parameters` (JSON-able;
        dimensionless, plus SI where they have units)."""


class AbstractForceTerm(AbstractExtension):
    """A history-free force term ``c theta(z, z')``: its column, sign (the term's physical
    sign), name and kernel encoding are the library term's."""

    _rank = 0

    @abc.abstractmethod
    def term(self) -> AbstractTerm:
        """The term as an :mod:`afmlearn.identify.library` term."""


class AbstractNeck(AbstractExtension):
    """The kernel's history-dependent law: the simulator's hysteretic JKR contact.

    With JKR constants ``r_j`` (tip radius / L_ref) and ``c_j`` (``sqrt(2 pi w / (E* L_ref))``)
    the contact radius ``a = s**2`` solves ``delta = s**4 / r_j - c_j s`` (``delta = a0 - z``)
    and the JKR force is ``alpha s**6 - beta s**3`` with ``beta = 1.5 r_j c_j alpha``
    (:class:`simulator.forces.HystereticJKR`, whose terms ``JKR_CUBE``, ``JKR_THREE_HALVES``
    the kernel integrates). The tip attaches at ``z <= a0`` and the neck breaks at its
    stability limit ``z = a0 + d_c``, ``d_c = 0.75 c_j s_m``, ``s_m = (c_j r_j / 4)**(1/3)``.

    The neck adds ONE column with a coefficient ``alpha >= 0`` (the JKR stiffness)::

        theta = [attached] (s**6 - 1.5 r_j c_j s**3 + 0.5 (r_j c_j)**2 (a0 / max(z, a0))**2)

    The last part cancels, while attached, the baseline's van der Waals term at the
    coefficient JKR continuity gives it (the tail meets the JKR force where contact forms,
    ``F(delta = 0) = -0.5 alpha (r_j c_j)**2``, as in the simulator): with ``alpha = 0`` the
    model is the baseline (nested), and ``c_vdw = -0.5 alpha (r_j c_j)**2 a0**2``,
    ``c_contact = 0`` is the simulator's hysteretic JKR law exactly. The column is zero where
    contact forms (``s**3 = r_j c_j``), so the force stays continuous there.
    """

    _rank = 1

    @abc.abstractmethod
    def contact_constants(self) -> tuple[float, float]:
        """``(r_j, c_j)``, both > 0 (dimensionless JKR radius and adhesion constants)."""

    @final
    def neck_length(self) -> float:
        """``d_c`` / L_ref: how far past contact the neck holds (its stability limit)."""
        r_j, c_j = self.contact_constants()
        return 0.75 * c_j * (c_j * r_j / 4.0) ** (1.0 / 3.0)

    @final
    def state(self, z: FloatArray, a0: float) -> NDArray[np.bool_]:
        """Attachment along one period of a periodic orbit, shape (n,) (:func:`neck_state`)."""
        return neck_state(z, a0, self.neck_length())

    @final
    def column(self, z: FloatArray, attached: NDArray[np.bool_], a0: float) -> FloatArray:
        """The neck's column (class docstring) on gaps ``z`` with attachment ``attached``
        (both shape (n,)); zero where not attached."""
        r_j, c_j = self.contact_constants()
        z = np.asarray(z, float)
        out = np.zeros(z.shape)
        att = np.asarray(attached, bool)
        if att.any():
            s3 = jkr_radius_sqrt(np.ascontiguousarray(a0 - z[att]), r_j, c_j) ** 3
            rc = r_j * c_j
            out[att] = s3 * s3 - 1.5 * rc * s3 + 0.5 * rc**2 * (a0 / np.maximum(z[att], a0)) ** 2
        return out

    @final
    def encode(self, a0: float) -> tuple[NDArray[np.int64], FloatArray, FloatArray, FloatArray]:
        """The column as :class:`simulator.forces.ForceLaw` terms ``(kinds, p1, p2, weights)``
        (each shape (4,)); the kernel's coefficients are ``alpha * weights``. The tail part
        is ``INVERSE_POWER - DETACHED_POWER`` (``max(z, a0)**-2`` while attached, else 0)."""
        r_j, c_j = self.contact_constants()
        rc = r_j * c_j
        tail = 0.5 * rc**2 * a0**2
        kinds = np.array([Kind.JKR_CUBE, Kind.JKR_THREE_HALVES, Kind.INVERSE_POWER,
                          Kind.DETACHED_POWER], np.int64)
        p1 = np.array([r_j, r_j, 2.0, 2.0])
        p2 = np.array([c_j, c_j, 0.0, 0.0])
        return kinds, p1, p2, np.array([1.0, -1.5 * rc, tail, -tail])


class AbstractExtraMode(AbstractExtension):
    """A second lever mode ``q2'' + D2 q2' + K2 q2 = g2 (drive - F_ts)``, ``x = q1 + q2``."""

    _rank = 2

    @abc.abstractmethod
    def mode_parameters(self) -> tuple[float, float, float]:
        """``(omega2/omega1, Q2, g2)``."""

    @final
    def modal(self) -> tuple[float, float, float]:
        """``(K2, D2, g2) = (ratio^2, ratio/Q2, g2)`` of the equation of motion."""
        ratio, q2, g2 = self.mode_parameters()
        return ratio**2, ratio / q2, g2

    @final
    def response(self, n: NDArray[np.int_], omega: float) -> NDArray[np.complex128]:
        """``H2_n = 1 / (K2 - (n Omega)^2 + i n Omega D2)``, shape of ``n``."""
        ratio, q2, _ = self.mode_parameters()
        return 1.0 / (ratio**2 - (n * omega) ** 2 + 1j * n * omega * ratio / q2)


class AbstractOutputMap(AbstractExtension):
    """The detector's instantaneous map ``y = x + b_2 x^2 + b_3 x^3 + ..`` of the true
    deflection (lengths / L_ref)."""

    _rank = 3

    @abc.abstractmethod
    def polynomial(self) -> tuple[float, ...]:
        """``(b_2, b_3, ..)`` [1/L_ref, 1/L_ref^2, ..]."""

    @final
    def measure(self, x: FloatArray) -> FloatArray:
        """Measured ``y`` of true deflection ``x`` (same shape)."""
        y = x
        for k, b in enumerate(self.polynomial(), start=2):
            y = y + b * x**k
        return y

    @final
    def invert(self, y: FloatArray) -> FloatArray:
        """True deflection of measured ``y`` (:func:`invert_polynomial`)."""
        return invert_polynomial(y, self.polynomial())


@final
@dataclass(frozen=True)
class ModelSpec:
    """Structure of a candidate model (see the module docstring).

    Parameters
    ----------
    a0 : float
        Contact onset / ``L_ref``, > 0.
    drive_phase : float
        ``phi`` of the drive ``B cos(Omega tau - phi)`` [rad], ``tau`` from the first sample.
    contact_exponent : float
        ``p`` of ``delta^p`` (1.5: sphere).
    extensions : tuple of AbstractExtension
        The causes' extensions (distinct keys; at most one neck, extra mode and output map).
        Stored in the canonical order (module docstring), not the order given: specs with
        the same extensions are equal and have the same :meth:`term_keys`.
    """

    a0: float
    drive_phase: float = 0.0
    contact_exponent: float = 1.5
    extensions: tuple[AbstractExtension, ...] = ()

    def __post_init__(self) -> None:
        exts = tuple(self.extensions)
        bad = [e for e in exts if not (isinstance(e, AbstractExtension) and e.key)]
        if bad:
            raise ValueError(f"extensions must be AbstractExtension objects with a key, got "
                             f"{bad!r}")
        keys = [e.key for e in exts]
        if len(set(keys)) != len(keys):
            raise ValueError(f"extensions must have distinct keys, got {keys}")
        for role in (AbstractNeck, AbstractExtraMode, AbstractOutputMap):
            if sum(isinstance(e, role) for e in exts) > 1:
                raise ValueError(f"extensions: at most one {role.__name__} (the kernel "
                                 f"integrates one), got {keys}")
        object.__setattr__(self, "extensions", tuple(sorted(exts, key=_canonical)))

    def replace(self, **changes: Any) -> ModelSpec:
        return dataclasses.replace(self, **changes)

    def with_extension(self, extension: AbstractExtension) -> ModelSpec:
        """This spec extended by ``extension`` (replacing the one with the same key; the
        result is in the canonical order, whatever the order of the calls)."""
        exts = list(self.extensions)
        keys = [e.key for e in exts]
        if extension.key in keys:
            exts[keys.index(extension.key)] = extension
        else:
            exts.append(extension)
        return self.replace(extensions=tuple(exts))

    def get(self, kind: type[E]) -> E | None:
        """The extension that is a ``kind`` (a concrete class or a role), or None."""
        return next((e for e in self.extensions if isinstance(e, kind)), None)

    # ---------------------------------------------------------------- roles
    @property
    def force_terms(self) -> tuple[AbstractForceTerm, ...]:
        return tuple(e for e in self.extensions if isinstance(e, AbstractForceTerm))

    @property
    def neck(self) -> AbstractNeck | None:
        return self.get(AbstractNeck)

    @property
    def extra_mode(self) -> AbstractExtraMode | None:
        return self.get(AbstractExtraMode)

    @property
    def output_map(self) -> AbstractOutputMap | None:
        return self.get(AbstractOutputMap)

    @property
    def state_key(self) -> tuple[str, ...]:
        """Keys of the extensions that change the state or the output (neck, extra mode,
        output map): models with the same state key share shooting warm starts."""
        return tuple(e.key for e in self.extensions if not isinstance(e, AbstractForceTerm))

    # ---------------------------------------------------------------- force terms
    def library(self) -> AFMLibrary:
        """The smooth (history-free) force terms as an :class:`AFMLibrary` (built once per
        spec: both are immutable)."""
        return self._library

    @functools.cached_property
    def _library(self) -> AFMLibrary:
        terms: list[Any] = [InversePower(n=2), Indentation(p=float(self.contact_exponent))]
        terms += [e.term() for e in self.force_terms]
        return AFMLibrary(terms)

    @property
    def n_force(self) -> int:
        """Number of force coefficients (library terms, then the neck's column)."""
        return self.library().n_terms + (self.neck is not None)

    def term_names(self) -> list[str]:
        names = list(self.library().names)
        if self.neck is not None:
            names += [self.neck.key]
        return names

    def term_keys(self) -> list[str]:
        """A stable key per force coefficient (which feature it belongs to), so that the
        coefficients of a nested model can be placed into an extension's vector."""
        keys = ["vdw", "contact", *(e.key for e in self.force_terms)]
        if self.neck is not None:
            keys.append(self.neck.key)
        return keys

    def embed(self, spec: ModelSpec, coef: FloatArray) -> FloatArray:
        """``coef = [K, D, B, c..]`` of a nested ``spec`` placed into this spec's layout (the
        columns this spec adds start at zero). The drive amplitudes of further drive groups,
        after the force coefficients (:mod:`~afmlearn.diagnose.joint`), are carried over."""
        return _relayout(coef, spec, self, src_in_dst=True)

    def restrict(self, full: ModelSpec, coef: FloatArray) -> FloatArray:
        """``coef`` of a spec ``full`` that nests this one, restricted to this spec's layout
        (the force coefficients of the columns this spec keeps; lever, drive and further drive
        amplitudes carried over): the inverse of :meth:`embed`."""
        return _relayout(coef, full, self, src_in_dst=False)

    def signs(self) -> list[int]:
        """Sign constraint of each force coefficient (+1 >= 0, -1 <= 0, 0 free)."""
        out = [int(t.sign) for t in self.library().terms]
        if self.neck is not None:
            out += [1]
        return out

    def state(self, z: FloatArray) -> NDArray[np.bool_]:
        """The neck's attachment along one period of a periodic orbit of gap ``z`` (shape
        (n,); all False without a neck)."""
        if self.neck is None:
            return np.zeros(np.shape(z), bool)
        return self.neck.state(z, self.a0)

    def columns(self, z: FloatArray, zdot: FloatArray, attached: NDArray[np.bool_] | None = None
                ) -> FloatArray:
        """Force columns on a trajectory, shape (n, n_force).

        ``attached`` (shape (n,)) is the neck state; needed when there is a neck.
        """
        s = TermInput(z=np.asarray(z, float), zdot=np.asarray(zdot, float),
                      x=np.zeros_like(z, dtype=float), a0=float(self.a0))
        cols = [self.library().evaluate(s)]
        if self.neck is not None:
            assert attached is not None
            cols.append(self.neck.column(z, attached, self.a0)[:, None])
        return np.column_stack(cols)


def _canonical(extension: AbstractExtension) -> tuple[int, int, str]:
    """Sort key of an extension in a spec: role, then :data:`FORCE_TERM_ORDER`, then key."""
    known = FORCE_TERM_ORDER.index(extension.key) if extension.key in FORCE_TERM_ORDER else None
    return (extension._rank, len(FORCE_TERM_ORDER) if known is None else known, extension.key)


def neck_state(z: FloatArray, a0: float, neck_length: float | None) -> NDArray[np.bool_]:
    """Attached (neck) state along one period of a periodic orbit, shape (n,).

    The tip attaches when ``z <= a0`` and detaches when ``z > a0 + neck_length``; the period is
    swept twice so that the state at its start is the one the orbit itself leaves there (the
    compiled :func:`~afmlearn.diagnose._kernel.neck_state`; all False without a neck).
    """
    z = np.ascontiguousarray(z, dtype=float).ravel()
    if neck_length is None:
        return np.zeros(z.size, bool)
    return _compiled_neck_state(z, float(a0), float(neck_length))


def invert_polynomial(y: FloatArray, coefficients: Sequence[float]) -> FloatArray:
    """True deflection ``x`` with ``y = x + b_2 x^2 + b_3 x^3 + ..`` (Newton from ``x = y``
    at every sample, the compiled :func:`~afmlearn.diagnose._kernel.invert_polynomial`;
    ``coefficients = (b_2, b_3, ..)``), shape of ``y``."""
    y = np.asarray(y, float)
    b = np.asarray(coefficients, float).ravel()
    return _compiled_invert(np.ascontiguousarray(y).ravel(), b).reshape(y.shape)


def _relayout(coef: FloatArray, src: ModelSpec, dst: ModelSpec, *,
              src_in_dst: bool) -> FloatArray:
    """``coef = [K, D, B, c.., further drive amplitudes]`` of ``src`` in ``dst``'s layout:
    lever, drive and further drive amplitudes carried over, force coefficients placed by their
    :meth:`ModelSpec.term_keys` (a column ``dst`` has and ``src`` has not starts at zero).
    ``src_in_dst``: every column of ``src`` must exist in ``dst`` (embedding a nested spec);
    else every column of ``dst`` must exist in ``src`` (restricting to a nested spec)."""
    coef = np.asarray(coef, float)
    src_keys, dst_keys = src.term_keys(), dst.term_keys()
    inner, outer = (src_keys, dst_keys) if src_in_dst else (dst_keys, src_keys)
    missing = [k for k in inner if k not in outer]
    assert not missing, f"spec columns {missing} are not nested"
    out = np.zeros(3 + dst.n_force + coef.size - 3 - src.n_force)
    out[:3] = coef[:3]
    out[3 + dst.n_force:] = coef[3 + src.n_force:]
    for j, key in enumerate(dst_keys):
        if key in src_keys:
            out[3 + j] = coef[3 + src_keys.index(key)]
    return out
