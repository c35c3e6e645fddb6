"""How the equation of motion becomes regression rows: the projection strategies.

Every strategy turns the training span of a trace into rows of

    target = xi_v * [x'] + xi_x * [x] + xi_c * [cos Omega tau] + xi_s * [sin Omega tau]
             - sum_j c_j [theta_j]

where ``[.]`` is the strategy's linear functional of a signal (a harmonic, an integral against
a test function). ``[x'']``, ``[x']``, ``[x]`` are taken on the measured deflection; the force
terms ``theta_j`` on the denoised state (``Denoised``), because a nonlinear function of noisy
data is biased. Rows come in time-ordered blocks for rolling cross-validation.

Strategies:

* :class:`HarmonicBalance` (periodic, steady-state data): rows are the harmonics of each block
  of whole periods, weighted by the inverse lever transfer function so that the row noise is
  white (generalised least squares); the noise of ``[x'']`` grows like ``n^2`` otherwise.
* :class:`~afmlearn.identify.weak.WeakForm` (any data: transients, approach): rows are integrals
  against compactly supported bumps, integrated by parts so no data derivative is taken.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray

from afmlearn.preprocess import HarmonicFit, fit_harmonics

from .library import AFMLibrary, TermInput

__all__ = ["AbstractProjection", "Bound", "Denoised", "HarmonicBalance", "RegressionData"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True, eq=False)
class Denoised:
    """The denoised state of the training span.

    Attributes
    ----------
    x, v : ndarray, shape (n,)
        Deflection / L_ref and its rate ``dx/dtau`` at the samples.
    harmonic_fit : HarmonicFit or None
        The periodic series behind ``x`` when the data are periodic.
    """

    x: FloatArray
    v: FloatArray
    harmonic_fit: HarmonicFit | None = None


@final
@dataclass(frozen=True, eq=False)
class RegressionData:
    """Training span of one trace, dimensionless.

    Attributes
    ----------
    tau : ndarray, shape (n,)
        ``omega0 t``.
    x : ndarray, shape (n,)
        Measured deflection / L_ref.
    omega : float
        Drive frequency / f0.
    quality_factor : float
        Calibrated Q (used for row weights only).
    gap : float
        Rest gap / L_ref.
    samples_per_period : float
    denoised : Denoised
    """

    tau: FloatArray
    x: FloatArray
    omega: float
    quality_factor: float
    gap: float
    samples_per_period: float
    denoised: Denoised


class Bound(abc.ABC):
    """A projection bound to data: the fixed columns plus the force-term columns on demand."""

    #: row index ranges of the time-ordered blocks, list of (start, stop)
    blocks: list[tuple[int, int]]
    #: target rows, shape (n_rows,)
    target: FloatArray
    #: columns [x', x, cos, sin], shape (n_rows, 4)
    linear: FloatArray

    @abc.abstractmethod
    def force_columns(self, library: AFMLibrary, a0: float, *,
                      gap_shift: float = 0.0) -> FloatArray:
        """``[theta_j]`` for every library term, shape (n_rows, n_terms).

        ``gap_shift`` (/ L_ref) is added to the gap the terms see (a per-observation orbit
        offset of a joint fit); strategies without it raise for a nonzero shift.
        """

    @property
    def n_rows(self) -> int:
        return int(self.target.shape[0])


class AbstractProjection(abc.ABC):
    """A projection strategy (configuration only); :meth:`bind` does the work."""

    @abc.abstractmethod
    def bind(self, data: RegressionData, *, n_blocks: int) -> Bound:
        """Precompute everything that does not depend on the library or ``a0``."""


@final
@dataclass(frozen=True)
class HarmonicBalance(AbstractProjection):
    """Harmonic-domain rows for periodic data (generalised least squares).

    Parameters
    ----------
    n_harmonics : int
        Harmonics per block (rows 0..n_harmonics, capped by the sampling's Nyquist limit).
        Harmonics below the noise floor are kept on purpose: the rows are weighted by the
        inverse transfer function, so noisy high harmonics cost little and still carry the
        contact's shape.
    grid : int
        Phase-grid points on which force terms are evaluated before their FFT (>= 8 x the
        number of harmonics; rounded up to a power of two).
    """

    n_harmonics: int = 40
    grid: int = 4096

    def __post_init__(self) -> None:
        if not (isinstance(self.n_harmonics, int) and self.n_harmonics >= 1):
            raise ValueError(f"n_harmonics must be an integer >= 1, got {self.n_harmonics!r}")
        if self.grid < 64:
            raise ValueError(f"grid must be >= 64 points, got {self.grid!r}")

    def bind(self, data: RegressionData, *, n_blocks: int) -> Bound:
        return _BoundHarmonic(self, data, n_blocks)


@final
class _BoundHarmonic(Bound):
    def __init__(self, cfg: HarmonicBalance, data: RegressionData, n_blocks: int) -> None:
        hf = data.denoised.harmonic_fit
        if hf is None:
            raise ValueError("HarmonicBalance needs periodic data (a harmonic fit); use WeakForm")
        spp = data.samples_per_period
        nh = int(min(cfg.n_harmonics, max(int(spp / 2) - 1, 1)))
        n_periods = int(data.x.size // spp)
        if n_periods < n_blocks:
            raise ValueError(f"HarmonicBalance needs at least n_blocks = {n_blocks} whole periods "
                             f"in the training span, got {n_periods}")
        edges = np.round(np.linspace(0, n_periods, n_blocks + 1) * spp).astype(int)
        om, q = data.omega, data.quality_factor
        n = np.arange(nh + 1)
        w = 1.0 / np.abs(1.0 - (n * om) ** 2 + 1j * n * om / q)
        w /= w[0]
        self.weights = w
        self.nh = nh
        tgt, lin, blocks = [], [], []
        row = 0
        for b in range(n_blocks):
            a, z = edges[b], edges[b + 1]
            Xb = fit_harmonics(data.tau[a:z], data.x[a:z], om, n_harmonics=nh).complex_amplitudes
            t = -(n * om) ** 2 * Xb
            cols = np.stack([1j * n * om * Xb, Xb, (n == 1).astype(complex),
                             -1j * (n == 1).astype(complex)], axis=1)
            tgt.append(self._rows(t * w))
            lin.append(self._rows(cols * w[:, None]))
            m = tgt[-1].shape[0]
            blocks.append((row, row + m))
            row += m
        self.target = np.concatenate(tgt)
        self.linear = np.concatenate(lin)
        self.blocks = blocks
        self.n_blocks = n_blocks
        # the orbit on a phase grid for the force terms
        m = 1 << int(np.ceil(np.log2(max(cfg.grid, 8 * nh))))
        phase = 2 * np.pi * np.arange(m) / m
        tau = phase / hf.base_frequency
        self._x = hf.evaluate(tau, 0)
        self._v = hf.evaluate(tau, 1)
        self._m = m
        self._gap = data.gap

    @staticmethod
    def _rows(c: NDArray[np.complex128]) -> FloatArray:
        """Real rows: Re of every harmonic, Im of harmonics >= 1 (Im of n = 0 is zero)."""
        c2 = c if c.ndim == 2 else c[:, None]
        out = np.concatenate([c2.real, c2[1:].imag], axis=0)
        return out if c.ndim == 2 else out[:, 0]

    def force_columns(self, library: AFMLibrary, a0: float, *,
                      gap_shift: float = 0.0) -> FloatArray:
        s = TermInput(z=self._gap + gap_shift - self._x, zdot=-self._v, x=self._x, a0=a0)
        th = library.evaluate(s)
        spec = np.fft.rfft(th, axis=0)[: self.nh + 1] / self._m
        spec[1:] *= 2.0  # theta = Re sum_n T_n e^{i n phi}
        one = self._rows(spec * self.weights[:, None])
        return np.concatenate([one] * self.n_blocks, axis=0)
