"""`ModelSpec`: the structure of a candidate model (baseline plus at most a few extensions).

Everything is dimensionless (lengths / ``L_ref``, time ``tau = omega0 t``, forces / ``k L_ref``).
The force is ``F_ts = sum_j c_j theta_j`` (``> 0`` repulsive) with the terms

====================  =====================================================  ==============
column                value                                                   sign of c_j
====================  =====================================================  ==============
``z^-2``              ``z^-2`` (held at ``a0`` in contact)                    <= 0 (attraction)
``delta^p``           ``(a0 - z)^p`` in contact (``p = contact_exponent``)    >= 0
``delta^q delta'``    visco-elastic ``(a0 - z)^q (-z')`` in contact           >= 0
``exp(-z/z_b) z'``    distance-decaying damping                               <= 0
``1/(z(z+R))``        sphere electrostatics (held at ``a0`` in contact)       <= 0
``neck``              ``(z - a0)/d_c`` while the neck holds (``a0 < z <= a0   <= 0
                      + d_c`` after contact, until it breaks): the extra pull
                      of a JKR neck over the van der Waals tail, zero where
                      contact forms and largest at the snap
====================  =====================================================  ==============

The lever is one mode (``K``, ``D``) or, with ``mode2 = (ratio, Q2, g2)``, two modes sharing
the tip force and drive with gains ``1`` and ``g2``; ``detector = (b2, b3)`` maps the true
deflection to the measured one, ``y = x + b2 x^2 + b3 x^3``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.identify.library import (
    AFMLibrary,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
    SphereElectrostatic,
    TermInput,
)

__all__ = ["ModelSpec", "neck_state"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True)
class ModelSpec:
    """Structure of a candidate model (see the module docstring); ``None`` = feature off.

    Parameters
    ----------
    a0 : float
        Contact onset / ``L_ref``, > 0.
    drive_phase : float
        ``phi`` of the drive ``B cos(Omega tau - phi)`` [rad], ``tau`` from the first sample.
    contact_exponent : float
        ``p`` of ``delta^p`` (1.5: sphere).
    visco_exponent : float or None
        ``q`` of the visco-elastic term ``delta^q delta'``.
    damping_decay : float or None
        ``z_b`` / ``L_ref`` of ``exp(-z/z_b) z'``.
    electrostatic_radius : float or None
        ``R`` / ``L_ref`` of ``1/(z(z+R))``.
    neck_length : float or None
        ``d_c`` / ``L_ref``: the neck breaks at ``z = a0 + d_c`` on retraction.
    mode2 : (float, float, float) or None
        ``(omega2/omega1, Q2, g2)`` of a second mode.
    detector : (float, float) or None
        ``(b2, b3)`` of the measured output ``y = x + b2 x^2 + b3 x^3`` [1/L_ref, 1/L_ref^2].
    """

    a0: float
    drive_phase: float = 0.0
    contact_exponent: float = 1.5
    visco_exponent: float | None = None
    damping_decay: float | None = None
    electrostatic_radius: float | None = None
    neck_length: float | None = None
    mode2: tuple[float, float, float] | None = None
    detector: tuple[float, float] | None = None

    def replace(self, **changes: Any) -> ModelSpec:
        return dataclasses.replace(self, **changes)

    # ---------------------------------------------------------------- force terms
    def library(self) -> AFMLibrary:
        """The smooth (history-free) force terms as an :class:`AFMLibrary`."""
        terms: list[Any] = [InversePower(n=2), Indentation(p=float(self.contact_exponent))]
        if self.visco_exponent is not None:
            terms.append(IndentationRate(p=float(self.visco_exponent), l=1))
        if self.damping_decay is not None:
            terms.append(ExponentialDamping(decay_length=float(self.damping_decay)))
        if self.electrostatic_radius is not None:
            terms.append(SphereElectrostatic(radius=float(self.electrostatic_radius)))
        return AFMLibrary(terms)

    @property
    def n_neck(self) -> int:
        return 0 if self.neck_length is None else 1

    @property
    def n_force(self) -> int:
        """Number of force coefficients (library terms, then neck columns)."""
        return self.library().n_terms + self.n_neck

    def term_names(self) -> list[str]:
        names = list(self.library().names)
        if self.neck_length is not None:
            names += ["neck"]
        return names

    def term_keys(self) -> list[str]:
        """A stable key per force coefficient (which feature it belongs to), so that the
        coefficients of a nested model can be placed into an extension's vector."""
        keys = ["vdw", "contact"]
        for key, on in (("visco", self.visco_exponent), ("damping", self.damping_decay),
                        ("electrostatic", self.electrostatic_radius),
                        ("neck", self.neck_length)):
            if on is not None:
                keys.append(key)
        return keys

    def embed(self, spec: ModelSpec, coef: FloatArray) -> FloatArray:
        """``coef = [K, D, B, c..]`` of a nested ``spec`` placed into this spec's layout (the
        columns this spec adds start at zero). The drive amplitudes of further drive groups,
        after the force coefficients (:mod:`~afmlearn.diagnose.joint`), are carried over."""
        coef = np.asarray(coef, float)
        extra = coef[3 + spec.n_force:]
        out = np.zeros(3 + self.n_force + extra.size)
        out[:3] = coef[:3]
        out[3 + self.n_force:] = extra
        mine = self.term_keys()
        for j, key in enumerate(spec.term_keys()):
            out[3 + mine.index(key)] = coef[3 + j]
        return out

    def signs(self) -> list[int]:
        """Sign constraint of each force coefficient (+1 >= 0, -1 <= 0, 0 free)."""
        out = [int(t.sign) for t in self.library().terms]
        if self.neck_length is not None:
            out += [-1]
        return out

    def columns(self, z: FloatArray, zdot: FloatArray, attached: NDArray[np.bool_] | None = None
                ) -> FloatArray:
        """Force columns on a trajectory, shape (n, n_force).

        ``attached`` (shape (n,)) is the neck state; needed when ``neck_length`` is set.
        """
        s = TermInput(z=np.asarray(z, float), zdot=np.asarray(zdot, float),
                      x=np.zeros_like(z, dtype=float), a0=float(self.a0))
        cols = [self.library().evaluate(s)]
        if self.neck_length is not None:
            assert attached is not None
            neck = attached & (z > self.a0)
            cols.append(np.where(neck, (z - self.a0) / self.neck_length, 0.0)[:, None])
        return np.column_stack(cols)


def neck_state(z: FloatArray, a0: float, neck_length: float | None) -> NDArray[np.bool_]:
    """Attached (neck) state along one period of a periodic orbit, shape (n,).

    The tip attaches when ``z <= a0`` and detaches when ``z > a0 + neck_length``; the period is
    swept twice so that the state at its start is the one the orbit itself leaves there.
    """
    n = z.size
    out = np.zeros(n, bool)
    if neck_length is None:
        return out
    on = False
    for sweep in range(2):
        for i in range(n):
            if z[i] <= a0:
                on = True
            elif z[i] > a0 + neck_length:
                on = False
            if sweep:
                out[i] = on
    return out
