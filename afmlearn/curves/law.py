"""The tip--sample law fitted to lock-in curves (dimensionless, the simulator's force terms).

The terms are those of :mod:`simulator.forces` (VdW--DMT contact with a free exponent, the
viscoelastic contact term, exponential damping, the sphere electrostatic tail) plus an adhesion
neck for hysteretic adhesion; :meth:`CurveLaw.force` is the plain NumPy reference of the
compiled evaluator :func:`afmlearn.curves._kernel.force`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _kernel

__all__ = ["CurveLaw"]


@final
@dataclass(frozen=True)
class CurveLaw:
    """Tip--sample force law, lengths / ``L_ref``, forces / ``k L_ref``, rates per ``omega0 t``.

    Parameters
    ----------
    a0 : float
        Contact onset (> 0).
    vdw : float
        ``-vdw / z**2`` out of contact (adhesion ``vdw / a0**2``), >= 0.
    stiffness, exponent : float
        Contact ``stiffness * delta**exponent``, ``delta = a0 - z``.
    visco : float
        Viscoelastic contact term ``visco * sqrt(delta) * delta_dot`` (>= 0).
    damping, decay_length : float
        Long-range damping ``-damping * exp(-z / decay_length) * z_dot`` (>= 0).
    electrostatic, radius : float
        Electrostatic tail ``-electrostatic / (z (z + radius))`` (>= 0).
    neck : float
        Adhesion neck: a contact breaks on retraction at ``z = a0 + neck`` (>= 0; 0 = none).
    far_damping, far_decay_length : float
        A second damping term ``-far_damping * exp(-z / far_decay_length) * z_dot`` (>= 0;
        0 = none): a loss far from the sample (squeeze-film damping over microns) next to the
        near-contact one of ``damping``. The two terms have the same form; which one is
        "near" is a matter of their bounds in the hypothesis (``hypotheses.py``).
    """

    a0: float
    vdw: float = 0.0
    stiffness: float = 1.0
    exponent: float = 1.5
    visco: float = 0.0
    damping: float = 0.0
    decay_length: float = 0.1
    electrostatic: float = 0.0
    radius: float = 1.0
    neck: float = 0.0
    far_damping: float = 0.0
    far_decay_length: float = 10.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not np.isfinite(v) or v < 0.0:
                raise ValueError(f"CurveLaw.{f.name} must be a finite number >= 0, got {v!r}")
        if (self.a0 <= 0.0 or self.decay_length <= 0.0 or self.radius <= 0.0
                or self.far_decay_length <= 0.0):
            raise ValueError("CurveLaw: a0, decay_length, far_decay_length and radius must be "
                             "> 0")
        if not 1.0 <= self.exponent <= 4.0:
            raise ValueError(f"CurveLaw.exponent must lie in [1, 4], got {self.exponent!r}")

    def vector(self) -> NDArray[np.float64]:
        """The compiled kernel's law vector, shape (12,) (layout in ``_kernel``)."""
        return np.array([self.a0, self.vdw, self.stiffness, self.exponent, self.visco,
                         self.damping, self.decay_length, self.electrostatic, self.radius,
                         self.neck, self.far_damping, self.far_decay_length])

    def replace(self, **changes: float) -> CurveLaw:
        return replace(self, **changes)

    def parameters(self) -> dict[str, Any]:
        return asdict(self)

    @property
    def adhesion(self) -> float:
        """Pull-off (adhesion) force ``vdw / a0**2``."""
        return self.vdw / self.a0**2

    def damping_terms(self) -> list[tuple[str, float, float]]:
        """The exponential damping terms that are on: ``(name, coefficient, decay_length)``,
        ``"near"`` (``damping``) then ``"far"`` (``far_damping``); coefficients in ``k / omega0``
        units (the lever's own damping is ``1 / Q`` in them), lengths / ``L_ref``."""
        return [(name, c, zb) for name, c, zb in (("near", self.damping, self.decay_length),
                                                  ("far", self.far_damping,
                                                   self.far_decay_length)) if c > 0.0]

    def conservative(self, z: ArrayLike) -> NDArray[np.float64]:
        """Conservative force on approach at gaps ``z`` (shape of ``z``), no rate terms."""
        return self.force(z, 0.0)

    def force(self, z: ArrayLike, zdot: ArrayLike = 0.0,
              mode: ArrayLike | None = None) -> NDArray[np.float64]:
        """NumPy reference of the force.

        Parameters
        ----------
        z : array-like, shape (...)
            Gap (> 0 out of contact).
        zdot : array-like, broadcastable to ``z``
            Gap rate.
        mode : array-like of int, broadcastable, optional
            0 free, 1 contact, 2 neck; default ``z <= a0`` (the approach branch).

        Returns
        -------
        ndarray, shape of ``z``
            Force, positive = repulsive.
        """
        z = np.asarray(z, dtype=float)
        zd = np.broadcast_to(np.asarray(zdot, dtype=float), z.shape)
        mode = (z <= self.a0).astype(int) if mode is None else np.broadcast_to(mode, z.shape)
        d = self.a0 - z
        zs = np.where(mode == 0, z, self.a0)
        contact = (-self.vdw / self.a0**2 + self.stiffness * np.sign(d) * np.abs(d)
                   ** self.exponent + self.visco * np.sqrt(np.abs(d)) * (-zd))
        out = np.where(mode == 1, contact, np.where(mode == 2, -self.vdw / self.a0**2,
                                                     -self.vdw / np.maximum(zs, 1e-300)**2))
        out = out - self.damping * np.exp(-z / self.decay_length) * zd
        out = out - self.far_damping * np.exp(-z / self.far_decay_length) * zd
        zl = np.where(mode == 1, self.a0, z)
        out = out - self.electrostatic / (zl * (zl + self.radius))
        return out

    def compiled(self, z: float, zdot: float, mode: int) -> float:
        """One evaluation of the compiled kernel (for tests)."""
        return float(_kernel.force(self.vector(), float(z), float(zdot), int(mode)))
