"""Shared force models, tapping set-ups and signal helpers for the simulator tests.

Imported by the test modules (``from simcases import ...``; pytest puts this folder on the path).

All quantities are dimensionless (``physics.md`` §1): lengths in units of the rest gap, forces
in units of ``k L_ref``, time ``tau = omega0 t``. The SI set-up below (k = 40 N/m,
f0 = 300 kHz, rest gap 10 nm) is only used where a model is built ``from_si``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simulator import Cantilever, Scales, System, TipExcitation
from simulator.forces import (
    DMT,
    JKR,
    AbstractForceModel,
    Electrostatic,
    ExponentialDamping,
    ForceSum,
    HystereticJKR,
    LennardJones,
    NoInteraction,
    SphereVdW,
    ViscoelasticDMT,
)

SCALES = Scales(spring_constant=40.0, resonance_frequency=300e3, length=10e-9)
#: DMT used throughout: contact at 0.2 rest gaps, adhesion vdw / a0**2 = 0.05, stiff contact
DMT_PARAMS = {"a0": 0.2, "vdw": 0.002, "stiffness": 20.0}


def hysteretic_jkr() -> HystereticJKR:
    """JKR neck for a 10 nm tip on a 10 GPa sample, w = 0.05 J/m^2, a0 = 0.3 nm."""
    return HystereticJKR.from_si(reduced_modulus_pa=10e9, tip_radius_m=10e-9,
                                 work_of_adhesion_j_per_m2=0.05, a0_m=0.3e-9, scales=SCALES)


#: one instance of every force model (and the sums the project uses), by test id
FORCE_MODELS: dict[str, AbstractForceModel] = {
    "none": NoInteraction(),
    "lj": LennardJones(repulsion=6.4e-7, attraction=0.01),
    "vdw_sphere": SphereVdW(strength=0.004, radius=1.0),
    "electrostatic": Electrostatic(strength=0.002, radius=1.0),
    "dmt": DMT(**DMT_PARAMS),
    "dmt_p2": DMT(**DMT_PARAMS, exponent=2.0),
    "dmt_p2.27": DMT(**DMT_PARAMS, exponent=2.27),
    "visco": ViscoelasticDMT(**DMT_PARAMS, viscosity=0.5),
    "visco_q1": ViscoelasticDMT(**DMT_PARAMS, exponent=2.0, viscosity=0.5,
                                viscosity_exponent=1.0),
    "dmt+expdamp": DMT(**DMT_PARAMS) + ExponentialDamping(coefficient=0.05, decay_length=0.2),
    "jkr": JKR(a0=0.2, vdw=0.0015, stiffness=20.0),
    "jkr_hysteretic": hysteretic_jkr(),
    "jkr_hysteretic+expdamp": hysteretic_jkr() + ExponentialDamping(coefficient=0.05,
                                                                     decay_length=0.2),
    "electrostatic+dmt": Electrostatic(strength=0.002, radius=1.0) + DMT(**DMT_PARAMS),
    "vdw_sphere+dmt": SphereVdW(strength=0.004, radius=1.0)
    + DMT(a0=0.2, vdw=0.0, stiffness=200.0),
    "sum3": ForceSum([DMT(**DMT_PARAMS), Electrostatic(strength=0.002, radius=1.0),
                      ExponentialDamping(coefficient=0.05, decay_length=0.2)]),
}

#: models whose tip--sample force is conservative (no loss over a closed orbit)
CONSERVATIVE = ("none", "lj", "vdw_sphere", "electrostatic", "dmt", "dmt_p2", "dmt_p2.27", "jkr",
                "electrostatic+dmt", "vdw_sphere+dmt")
DISSIPATIVE = ("visco", "visco_q1", "dmt+expdamp", "jkr_hysteretic", "jkr_hysteretic+expdamp",
               "sum3")


@dataclass(frozen=True)
class Tapping:
    """A single-mode, tip-driven set-up at ``omega = 1`` (Q = 100, rest gap 1)."""

    name: str
    system: System
    omega: float
    substeps: int | None  # None: RK4's automatic choice


#: free amplitude per model: deep enough to tap (LJ needs more to reach its z**-8 wall);
#: the long-range-only models are run in the attractive (non-contact) regime
_FREE_AMPLITUDE = {"lj": 2.0, "vdw_sphere": 0.5, "electrostatic": 0.5}
_SUBSTEPS = {"lj": 8}  # the automatic step choice does not see the z**-8 wall


def tapping(name: str, *, n_modes: int = 1, quality_factor: float = 100.0) -> Tapping:
    cl = Cantilever.rectangular(n_modes=n_modes, quality_factor=quality_factor)
    exc = TipExcitation.for_free_amplitude(cl, 1.0, _FREE_AMPLITUDE.get(name, 1.5))
    return Tapping(name, System(cl, FORCE_MODELS[name], exc), 1.0, _SUBSTEPS.get(name))


def lockin(x: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Complex amplitude ``X`` of ``x = Re(X exp(i phase))`` over whole periods.

    Parameters
    ----------
    x, phase : ndarray, shape (..., n)
        Samples covering an integer number of drive periods, equally spaced in time.
    """
    return 2.0 * np.mean(x * np.exp(-1j * phase), axis=-1)


def mechanical_energy(system: System, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Kinetic + modal potential energy ``sum_i (v_i**2 + K_i q_i**2) / 2``, shape (B,)."""
    k = np.asarray(system.cantilever.stiffness)
    return 0.5 * np.sum(v**2 + k * q**2, axis=-1)


def two_pi_over(n: int, omega: float = 1.0) -> float:
    """Sample interval giving ``n`` samples per drive period."""
    return 2.0 * math.pi / (omega * n)
