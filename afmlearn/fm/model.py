"""The tip--sample law of an FM spectroscopy Δf(z, V): one force law shared by all biases.

The force (positive = repulsive, ``physics.md`` sections 1 and 3) at the gap ``d`` and tip
bias ``V`` is the project's :class:`~simulator.forces.law.ForceLaw` of

* van der Waals sphere--plane ``-s / (d**2 (d + 2R)**2)``, ``s = (2/3) H R**3`` (``SPHERE_VDW``);
* DMT contact repulsion ``(4/3) E* sqrt(R) (a0 - d)**1.5`` for ``d <= a0`` (``INDENTATION``);
* electrostatic sphere--plane ``-pi eps0 R_e**2 (V - V_cpd)**2 / (D (D + R_e))``,
  ``D = d + s_e`` (``SPHERE_ELECTROSTATIC``; prefactor fixed by ``R_e``: no free amplitude).
  ``R_e`` and the set-back ``s_e`` are their own parameters: on the measured map a sphere
  sharing the contact's ``R`` and gap cannot give the finite bias effect seen at contact (the
  electrostatic sphere is the blunt tip behind a sharp apex, or a dielectric layer);
* a bias-dependent far-field gradient ``k_far (V - V_far)**2`` [N/m per V**2], the cantilever
  (prong) and tip-cone capacitance, which change little over a few tens of nm: a constant
  shift per ``(V - V_far)**2``. Its potential ``V_far`` is the CPD averaged over the large
  area the lever sees, which need not equal the apex's ``V_cpd``: the sum of two parabolas is
  a parabola whose vertex moves from ``V_cpd`` (close) towards ``V_far`` (far), the
  distance-dependent CPD of the per-position parabolas;

plus two nuisances of the measurement: the piezo position ``z_contact_m`` at which the lower
turning point touches (``d = z_piezo - z_contact``), and a Δf offset (reference frequency).
``baseline`` laws drop the electrostatic terms (no bias dependence at all).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afmlearn.fm.forward import law_force
from simulator.forces.electrostatic import EPSILON_0
from simulator.forces.law import ForceLaw, Kind, Term

__all__ = ["A0_M", "FMLaw"]

#: contact onset a0 [m] (intermolecular distance; fixed: with a free z offset it is degenerate)
A0_M = 0.2e-9


@final
@dataclass(frozen=True)
class FMLaw:
    """Fitted (or true) parameters, SI units.

    Parameters
    ----------
    hamaker_j : float
        Hamaker constant H [J], >= 0.
    modulus_pa : float
        Effective contact modulus E* [Pa], >= 0.
    tip_radius_m : float
        Tip radius R [m], > 0 (van der Waals, contact and electrostatic sphere).
    vcpd_v : float
        Contact potential difference [V] (electrostatic force vanishes at ``V = vcpd_v``).
    es_radius_m : float
        Electrostatic sphere radius ``R_e`` [m], > 0.
    es_setback_m : float
        ``s_e`` [m], >= 0: the electrostatic sphere's gap is ``d + s_e``.
    far_gradient_n_per_m_v2 : float
        ``k_far = dF/dd`` per ``(V - V_far)**2`` [N/m / V**2], the bias-dependent far-field
        force gradient (>= 0 for an attraction that grows towards the sample; it shifts Δf by
        ``-f0 k_far (V - V_far)**2 / (2 k)`` at every gap).
    far_vcpd_v : float or None
        ``V_far`` [V]; None: equal to ``vcpd_v``.
    z_contact_m : float
        Piezo position [m] where the gap at the lower turning point is zero.
    offset_hz : float
        Δf offset [Hz].
    electrostatic : bool
        False for the baseline law (no bias-dependent terms).
    """

    hamaker_j: float
    modulus_pa: float
    tip_radius_m: float
    vcpd_v: float = 0.0
    es_radius_m: float = 1e-8
    es_setback_m: float = 0.0
    far_gradient_n_per_m_v2: float = 0.0
    far_vcpd_v: float | None = None
    z_contact_m: float = 0.0
    offset_hz: float = 0.0
    electrostatic: bool = True

    def __post_init__(self) -> None:
        for name in ("tip_radius_m", "es_radius_m"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("hamaker_j", "modulus_pa"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {getattr(self, name)!r}")

    def law(self, *, length_m: float, spring_constant_n_per_m: float
            ) -> ForceLaw:
        """The bias-independent :class:`ForceLaw` (vdW + DMT contact; lengths / ``length_m``,
        forces / ``k length_m``)."""
        ell, k = float(length_m), float(spring_constant_n_per_m)
        r = self.tip_radius_m / ell
        s_vdw = 2.0 * self.hamaker_j * r**3 / (3.0 * k * ell**2)
        c_rep = 4.0 / 3.0 * self.modulus_pa * math.sqrt(self.tip_radius_m * ell) / k
        terms = [Term(Kind.SPHERE_VDW, -s_vdw, r), Term(Kind.INDENTATION, c_rep, 1.5)]
        return ForceLaw(tuple(terms), a0=A0_M / ell, has_contact=True)

    def electrostatic_law(self, bias_v: float, *, length_m: float,
                          spring_constant_n_per_m: float) -> ForceLaw:
        """The electrostatic sphere as a :class:`ForceLaw` of ``D = d + s_e`` (no contact
        branch: ``D >= s_e``), lengths / ``length_m``, forces / ``k length_m``."""
        ell, k = float(length_m), float(spring_constant_n_per_m)
        s_es = (math.pi * EPSILON_0 * self.es_radius_m**2 * (bias_v - self.vcpd_v) ** 2
                / (k * ell**3)) if self.electrostatic else 0.0
        return ForceLaw((Term(Kind.SPHERE_ELECTROSTATIC, -s_es, self.es_radius_m / ell),),
                        a0=A0_M / ell, has_contact=False)

    def force_n(self, gap_m: ArrayLike, bias_v: float, *, spring_constant_n_per_m: float,
                reference_gap_m: float | None = None) -> NDArray[np.float64]:
        """Force [N] at gaps ``gap_m`` [m] (any shape) and one bias, positive = repulsive.

        The far-field gradient term is a force linear in the gap; it is included relative to
        ``reference_gap_m`` (0 there), and left out when that is None.
        """
        ell = 1e-9
        law = self.law(length_m=ell, spring_constant_n_per_m=spring_constant_n_per_m)
        d = np.asarray(gap_m, float)
        f = law_force(law, d / ell) * spring_constant_n_per_m * ell
        if self.electrostatic:
            es = self.electrostatic_law(bias_v, length_m=ell,
                                        spring_constant_n_per_m=spring_constant_n_per_m)
            f = f + law_force(es, (d + self.es_setback_m) / ell) * spring_constant_n_per_m * ell
        if reference_gap_m is not None and self.electrostatic:
            f = f - (self.far_gradient_n_per_m_v2 * (bias_v - self.far_v) ** 2
                     * (reference_gap_m - d))
        return f

    @property
    def far_v(self) -> float:
        """``V_far`` [V] (``vcpd_v`` when not set separately)."""
        return self.vcpd_v if self.far_vcpd_v is None else float(self.far_vcpd_v)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
