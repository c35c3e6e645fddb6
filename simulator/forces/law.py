"""The one force-law representation: a sum of coded terms ``F = sum_j c_j theta_j``.

Every tip--sample force in the project -- the simulator's models (``forces/*.py``), the
identifier's library terms (``afmlearn.identify.library``) and the diagnosis' candidates -- is
written as a :class:`ForceLaw`: a list of terms, each a family code (:class:`Kind`), two shape
parameters ``p1, p2`` and a coefficient, plus the contact onset ``a0`` and the regime switches.
The compiled evaluator :func:`simulator.forces._kernel.law_force` and the one integrator kernel
(``simulator/integrate/_kernel.py``) read only this encoding.

Terms are functions of the gap ``z``, its rate ``z'``, the deflection ``x`` (all dimensionless)
and two regime flags (``physics.md`` section 1: ``F > 0`` repulsive, ``delta = a0 - z``):

* ``contact`` -- the tip touches (``z <= a0``). Read from the gap by the library and the
  diagnosis, carried by the simulator as a state switched only at located events;
* ``attached`` -- a hysteretic regime that forms with contact and breaks at
  ``z = a0 + break_distance`` on retraction (JKR neck, capillary neck). Without hysteresis
  (``break_distance = 0``) it equals ``contact``.

=============================  =====================  ==========================================
kind                           p1, p2                 theta
=============================  =====================  ==========================================
CONSTANT                       --                     ``1``
DEFLECTION_POWER               k                      ``x**k`` (integer k)
INVERSE_POWER                  n                      ``z**-n``; ``a0**-n`` in contact (held)
CONTACT                        --                     ``[contact]``
INDENTATION                    p                      ``delta**p [contact]``
INDENTATION_RATE               p, l                   ``delta**p (-z')**l [contact]``
GAP_RATE                       p, l                   ``z**p z'**l [not contact]``
EXPONENTIAL_DAMPING            z_b                    ``exp(-z / z_b) z'``
SPHERE_ELECTROSTATIC           R                      ``1 / (z (z + R))``, held at ``a0`` in contact
SPHERE_VDW                     R                      ``1 / (z**2 (z + 2R)**2)``, held at ``a0``
JKR_CUBE                       r_j, c_j               ``a**3 [attached]``, JKR contact radius ``a``
JKR_THREE_HALVES               r_j, c_j               ``a**1.5 [attached]``
DETACHED_POWER                 n                      ``z**-n [not attached]``
NECK                           d_c                    ``(z - a0) / d_c [attached, not contact]``
=============================  =====================  ==========================================

The JKR radius solves ``delta = a**2 / r_j - c_j sqrt(a)`` on its stable branch. Powers of the
indentation are extended oddly (``sign(delta) |delta|**p``) so that Runge--Kutta stages may step
a little past a switch without producing NaN. Codes 1--9 are the identifier library's
(``afmlearn.identify.library.base.Kind``), which encodes its terms directly in this form.

Adding a term family: a code here, its value in ``_kernel.term_value``, a NumPy reference in the
model or library term that uses it, and a kernel-vs-reference test.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import final

import numpy as np
from numpy.typing import NDArray

__all__ = ["Kind", "ForceLaw", "Term", "pack_laws"]


@final
class Kind:
    """Integer codes of the term families understood by the compiled evaluator."""

    CONSTANT = 1
    DEFLECTION_POWER = 2
    INVERSE_POWER = 3
    CONTACT = 4
    INDENTATION = 5
    INDENTATION_RATE = 6
    GAP_RATE = 7
    EXPONENTIAL_DAMPING = 8
    SPHERE_ELECTROSTATIC = 9
    SPHERE_VDW = 10
    JKR_CUBE = 11
    JKR_THREE_HALVES = 12
    DETACHED_POWER = 13
    NECK = 14

    #: families that depend on the gap rate (dissipative candidates)
    RATE = (INDENTATION_RATE, GAP_RATE, EXPONENTIAL_DAMPING)
    #: families gated by the ``contact`` flag (need a switch located at ``z = a0``)
    CONTACT_GATED = (INVERSE_POWER, CONTACT, INDENTATION, INDENTATION_RATE, GAP_RATE,
                     SPHERE_ELECTROSTATIC, SPHERE_VDW, NECK)


@final
@dataclass(frozen=True)
class Term:
    """One term ``coef * theta_kind(z, z', x; p1, p2)`` (see the module table)."""

    kind: int
    coef: float
    p1: float = 0.0
    p2: float = 0.0


@final
@dataclass(frozen=True)
class ForceLaw:
    """A tip--sample force as a sum of coded terms, with its contact onset and hysteresis.

    Parameters
    ----------
    terms : sequence of Term
        The terms (may be empty: no force).
    a0 : float
        Contact onset / ``L_ref`` (0 when the law has no contact branch).
    has_contact : bool
        True when the law switches regime at ``z = a0`` (located events in the integrator).
    break_distance : float
        ``>= 0``: the attached regime breaks at ``z = a0 + break_distance`` on retraction
        (0: no hysteresis, ``attached == contact``).
    """

    terms: tuple[Term, ...] = ()
    a0: float = 0.0
    has_contact: bool = False
    break_distance: float = 0.0
    _arrays: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        if not (np.isfinite(self.a0) and self.a0 >= 0.0):
            raise ValueError(f"a0 must be finite and >= 0, got {self.a0!r}")
        if not (np.isfinite(self.break_distance) and self.break_distance >= 0.0):
            raise ValueError(f"break_distance must be finite and >= 0, got "
                             f"{self.break_distance!r}")
        kinds = np.array([t.kind for t in self.terms], np.int64)
        p1 = np.array([t.p1 for t in self.terms], float)
        p2 = np.array([t.p2 for t in self.terms], float)
        coefs = np.array([t.coef for t in self.terms], float)
        object.__setattr__(self, "_arrays", (kinds, p1, p2, coefs))

    @classmethod
    def from_arrays(cls, kinds: NDArray[np.int64], p1: NDArray[np.float64],
                    p2: NDArray[np.float64], coefs: NDArray[np.float64], *, a0: float,
                    has_contact: bool = True, break_distance: float = 0.0) -> ForceLaw:
        """From the flat encoding (each array shape (n_terms,)), e.g. a library's ``encode()``."""
        terms = tuple(Term(int(k), float(c), float(a), float(b))
                      for k, a, b, c in zip(kinds, p1, p2, coefs, strict=True))
        return cls(terms, a0=float(a0), has_contact=has_contact,
                   break_distance=float(break_distance))

    @property
    def arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64],
                              NDArray[np.float64]]:
        """``(kinds int64, p1, p2, coefs)``, each shape (n_terms,), for the compiled kernels."""
        return self._arrays

    @property
    def n_terms(self) -> int:
        return len(self.terms)

    @property
    def gates_on_contact(self) -> bool:
        """True when some nonzero term switches at ``z = a0`` (not only at the break)."""
        return any(t.kind in Kind.CONTACT_GATED and t.coef != 0.0 for t in self.terms)

    @property
    def dissipative(self) -> bool:
        """True if the law can dissipate energy over a closed orbit (rate terms, hysteresis)."""
        return self.break_distance > 0.0 or any(
            t.kind in Kind.RATE and t.coef != 0.0 for t in self.terms)

    def header(self) -> NDArray[np.float64]:
        """``[a0, has_contact, break_distance, gates_on_contact]``, shape (4,), for the kernel."""
        return np.array([self.a0, float(self.has_contact), self.break_distance,
                         float(self.gates_on_contact)])

    def coefficient(self, kind: int, p1: float | None = None) -> float:
        """Sum of the coefficients of the terms of ``kind`` (and shape ``p1`` if given)."""
        return float(sum(t.coef for t in self.terms
                         if t.kind == kind and (p1 is None or t.p1 == p1)))

    def __add__(self, other: ForceLaw) -> ForceLaw:
        """Superposition; at most one of the two may have a contact branch."""
        if not isinstance(other, ForceLaw):
            return NotImplemented
        if self.has_contact and other.has_contact:
            raise ValueError("force: a model may hold only one contact law")
        if self.has_contact:
            a0, brk = self.a0, self.break_distance
        else:
            a0, brk = other.a0, other.break_distance
        return ForceLaw(self.terms + other.terms, a0=a0,
                        has_contact=self.has_contact or other.has_contact, break_distance=brk)


def pack_laws(laws: Sequence[ForceLaw]) -> tuple[NDArray[np.int64], NDArray[np.float64],
                                                 NDArray[np.float64], NDArray[np.float64],
                                                 NDArray[np.float64]]:
    """Batch encoding ``(kinds, p1, p2, coefs)`` each (B, T) zero-padded, header (B, 4)."""
    b = len(laws)
    t = max([1] + [law.n_terms for law in laws])
    kinds = np.zeros((b, t), np.int64)
    p1 = np.zeros((b, t))
    p2 = np.zeros((b, t))
    coefs = np.zeros((b, t))
    hdr = np.zeros((b, 4))
    for i, law in enumerate(laws):
        k, a, c, w = law.arrays
        n = k.size
        kinds[i, :n], p1[i, :n], p2[i, :n], coefs[i, :n] = k, a, c, w
        hdr[i] = law.header()
    return kinds, p1, p2, coefs, hdr
