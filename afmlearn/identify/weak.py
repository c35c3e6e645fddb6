"""Weak (integral) formulation of the equation of motion: no derivative of noisy data.

Each row of the regression is the equation of motion integrated against a compactly supported
test function ``phi_k(tau)`` (a bump of half-width ``h`` centred on ``c_k``):

    int phi_k x'' dtau = int phi_k'' x dtau              (integration by parts, phi_k = 0 at ends)
    int phi_k x'  dtau = -int phi_k' x dtau
    int phi_k g(z) z' dtau = -int phi_k' G(z) dtau        (G' = g: damping terms have potentials)

so the target and the linear/dissipative columns are linear functionals of the measured data,
and noise enters the target only through a smooth kernel instead of a second difference.
Nonlinear force terms are integrated on the denoised state (see ``identifier.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy.signal import fftconvolve

from .library import AFMLibrary, TermInput
from .projection import AbstractProjection, Bound, RegressionData

__all__ = ["WeakForm"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True)
class WeakForm(AbstractProjection):
    """Bump test functions ``phi(s) = (1 - s^2)^order`` on ``|s| <= 1``, ``s = (tau - c)/h``.

    Parameters
    ----------
    half_width : float
        ``h`` in drive periods (> 0). Narrow windows keep the harmonics that carry the
        contact; wide ones average more noise.
    stride : float
        Distance between neighbouring centres in drive periods (> 0).
    order : int
        Smoothness ``>= 3`` so that ``phi``, ``phi'`` and ``phi''`` vanish at the window ends.
    """

    half_width: float = 0.25
    stride: float = 0.02
    order: int = 4

    def __post_init__(self) -> None:
        if not self.half_width > 0:
            raise ValueError(f"half_width must be > 0 drive periods, got {self.half_width!r}")
        if not self.stride > 0:
            raise ValueError(f"stride must be > 0 drive periods, got {self.stride!r}")
        if int(self.order) != self.order or self.order < 3:
            raise ValueError(f"order must be an integer >= 3, got {self.order!r}")

    def kernels(self, samples_per_period: float, dtau: float
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Sampled ``phi``, ``phi'``, ``phi''`` (derivatives w.r.t. tau) times ``dtau``.

        Returns three arrays of shape (2 K + 1,), ``K = round(half_width * samples_per_period)``.
        """
        k = max(int(round(self.half_width * samples_per_period)), 3)
        s = np.arange(-k, k + 1) / k
        h = k * dtau
        m = int(self.order)
        u = 1.0 - s * s
        phi = u ** m
        dphi = -2.0 * m * s * u ** (m - 1) / h
        ddphi = (-2.0 * m * u ** (m - 1) + 4.0 * m * (m - 1) * s * s * u ** (m - 2)) / h ** 2
        return phi * dtau, dphi * dtau, ddphi * dtau

    def centres(self, n_samples: int, samples_per_period: float) -> NDArray[np.int64]:
        """Sample indices of the window centres, shape (n_rows,)."""
        k = max(int(round(self.half_width * samples_per_period)), 3)
        step = max(int(round(self.stride * samples_per_period)), 1)
        if n_samples < 2 * k + 1:
            raise ValueError(
                f"trace too short for the weak form: {n_samples} samples < one window "
                f"({2 * k + 1} samples); lower half_width or record longer")
        return np.arange(k, n_samples - k, step)

    def project(self, f: FloatArray, kernel: FloatArray, centres: NDArray[np.int64]
                ) -> FloatArray:
        """``int kernel_k f dtau`` at each centre; ``f`` shape (n,) or (n, m) -> (n_rows[, m])."""
        k = (kernel.size - 1) // 2
        f2 = f[:, None] if f.ndim == 1 else f
        # correlation with the (symmetric-support) kernel: out[i] = sum_j kernel[j] f[i - k + j]
        full = fftconvolve(f2, kernel[::-1, None], mode="valid", axes=0)
        out = full[centres - k]
        return out[:, 0] if f.ndim == 1 else out

    def bind(self, data: RegressionData, *, n_blocks: int) -> Bound:
        return _BoundWeak(self, data, n_blocks)


@final
class _BoundWeak(Bound):
    def __init__(self, cfg: WeakForm, data: RegressionData, n_blocks: int) -> None:
        spp = data.samples_per_period
        dtau = float(data.tau[1] - data.tau[0])
        phi, dphi, ddphi = cfg.kernels(spp, dtau)
        cen = cfg.centres(data.x.size, spp)
        if cen.size < 2 * n_blocks:
            raise ValueError(f"WeakForm: {cen.size} windows are too few for {n_blocks} blocks; "
                             f"record longer or lower stride/half_width")
        self._cfg, self._phi, self._dphi, self._cen = cfg, phi, dphi, cen
        x = data.x
        th = data.omega * data.tau
        self.target = cfg.project(x, ddphi, cen)
        self.linear = np.stack([-cfg.project(x, dphi, cen), cfg.project(x, phi, cen),
                                cfg.project(np.cos(th), phi, cen),
                                cfg.project(np.sin(th), phi, cen)], axis=1)
        edges = np.round(np.linspace(0, cen.size, n_blocks + 1)).astype(int)
        self.blocks = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]
        self._state = data.denoised
        self._gap = data.gap

    def force_columns(self, library: AFMLibrary, a0: float, *,
                      gap_shift: float = 0.0) -> FloatArray:
        d = self._state
        s = TermInput(z=self._gap + gap_shift - d.x, zdot=-d.v, x=d.x, a0=a0)
        out = np.empty((self._cen.size, library.n_terms))
        plain = []
        for j, term in enumerate(library.terms):
            g = term.potential(s)
            if g is None:
                plain.append(j)
            else:
                out[:, j] = -self._cfg.project(g, self._dphi, self._cen)
        if plain:
            vals = np.stack([library.terms[j].evaluate(s) for j in plain], axis=1)
            out[:, plain] = self._cfg.project(vals, self._phi, self._cen)
        return out
