"""Harmonics of a free oscillation block by block, on the fundamental's own phase.

Each block of ``block_periods`` periods is fitted with `afmlearn.preprocess.fit_harmonics` in
the tracked phase ``phi(t)`` of the fundamental (``tau = phi``, ``omega = 1``), so a drifting
or frequency-modulated oscillation is still a Fourier series with fixed coefficients inside a
block. At ~19 samples per period the series is limited to 9 harmonics (Nyquist of the
sampling): fitting on the known phase needs no 20-samples-per-period margin, unlike the
derivative-based identification.

Per block the harmonic ``X_n`` is rotated by the fundamental's phase,
``R_n = X_n exp(-i n arg X_1)``: a harmonic locked to the fundamental (an instantaneous map, a
force that follows the motion) has a constant ``arg R_n`` (0 or pi for a real map or a
high-Q transfer function), whatever the oscillation's own phase.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afmlearn.freeosc.demodulate import Demodulation
from afmlearn.preprocess.harmonics import fit_harmonics

__all__ = ["HarmonicTrack", "ScalingFit", "track_harmonics", "amplitude_scaling"]

FloatArray = NDArray[np.float64]


@final
@dataclass(frozen=True, eq=False)
class HarmonicTrack:
    """Per-block harmonic content of a free oscillation.

    Attributes
    ----------
    time_s : ndarray, shape (n_blocks,)
        Block centres [s].
    offset : ndarray, shape (n_blocks,)
        Block mean (series constant ``c0``), units of the record.
    harmonics : ndarray of complex, shape (n_blocks, n_harmonics)
        ``R_n`` for n = 1..n_harmonics (``R_1 = |X_1|`` real), units of the record.
    noise_rms : ndarray, shape (n_blocks,)
        Residual standard deviation of each block's fit, units of the record.
    n_samples : ndarray of int, shape (n_blocks,)
        Samples per block.
    """

    time_s: FloatArray
    offset: FloatArray
    harmonics: NDArray[np.complex128]
    noise_rms: FloatArray
    n_samples: NDArray[np.int64]

    @property
    def amplitude(self) -> FloatArray:
        """Fundamental amplitude ``|X_1|`` per block, shape (n_blocks,)."""
        return self.harmonics[:, 0].real

    @property
    def relative(self) -> FloatArray:
        """``|X_n| / |X_1|``, shape (n_blocks, n_harmonics)."""
        return np.abs(self.harmonics) / self.amplitude[:, None]

    @property
    def harmonic_sigma(self) -> FloatArray:
        """Standard error of each block's ``Re R_n`` and ``Im R_n`` (white noise), shape
        (n_blocks,), units of the record: ``noise_rms sqrt(2 / n_samples)``."""
        return self.noise_rms * np.sqrt(2.0 / self.n_samples)


def track_harmonics(y: ArrayLike, demod: Demodulation, *, n_harmonics: int = 9,
                    block_periods: int = 200) -> HarmonicTrack:
    """Fit the harmonics of ``y`` block by block on the tracked phase.

    Parameters
    ----------
    y : array-like, shape (n,)
        The record, units of the record.
    demod : Demodulation
        Its demodulated fundamental (same samples); only ``valid`` samples are used.
    n_harmonics : int, default 9
        Harmonics per block, 1 .. Nyquist limit of the sampling.
    block_periods : int, default 200
        Block length in periods of the fundamental, >= 4.

    Returns
    -------
    HarmonicTrack

    Raises
    ------
    ValueError
        When no complete block fits in the valid span, or on settings out of range.
    """
    y = np.asarray(y, dtype=float)
    if y.shape != demod.phase.shape:
        raise ValueError(f"y must have the demodulation's shape {demod.phase.shape}, "
                         f"got {y.shape}")
    if isinstance(block_periods, bool) or not isinstance(block_periods, int | np.integer) \
            or block_periods < 4:
        raise ValueError(f"block_periods must be an integer >= 4, got {block_periods!r}")
    idx = np.flatnonzero(demod.valid)
    phase = demod.phase[idx]
    cycle = np.floor((phase - phase[0]) / (2 * math.pi * block_periods)).astype(np.int64)
    edges = np.flatnonzero(np.diff(cycle)) + 1
    starts = np.r_[0, edges]
    stops = np.r_[edges, idx.size]
    complete = np.ones(starts.size, dtype=bool)
    complete[-1] = (phase[-1] - phase[starts[-1]]) >= 2 * math.pi * block_periods * 0.999
    if not complete.any():
        raise ValueError(f"block_periods={block_periods} is longer than the valid record "
                         f"({(phase[-1] - phase[0]) / (2 * math.pi):.0f} periods)")
    rows = []
    for a, b in zip(starts[complete], stops[complete], strict=True):
        sel = idx[a:b]
        fit = fit_harmonics(demod.phase[sel], y[sel], 1.0, n_harmonics=n_harmonics)
        xk = fit.complex_amplitudes
        rot = np.exp(-1j * np.angle(xk[1]) * np.arange(1, xk.size))
        rows.append((demod.time_s[sel].mean(), xk[0].real, xk[1:] * rot, fit.noise_rms, sel.size))
    t, c0, h, s, m = zip(*rows, strict=True)
    harm = np.array(h)
    harm[:, 0] = np.abs(harm[:, 0])
    return HarmonicTrack(time_s=np.array(t), offset=np.array(c0), harmonics=harm,
                         noise_rms=np.array(s), n_samples=np.array(m, dtype=np.int64))


@final
@dataclass(frozen=True)
class ScalingFit:
    """Power law ``|X_n| ~ |X_1|^p`` across blocks.

    Attributes
    ----------
    harmonic : int
        n.
    exponent : float
        p (an instantaneous map or a force expanded in the motion: p = n; a drive of fixed
        amplitude: p = 0; a detector gain drift at a fixed map: p = 1).
    stderr : float
        Standard error of p (least squares in logs, residual-scaled).
    log_amplitude_range : float
        ``ln(max |X_1| / min |X_1|)`` over the blocks: the lever arm of the fit.
    """

    harmonic: int
    exponent: float
    stderr: float
    log_amplitude_range: float


def amplitude_scaling(track: HarmonicTrack, harmonic: int) -> ScalingFit:
    """Fit ``ln |X_n| = ln c + p ln |X_1|`` over the blocks of ``track``.

    Parameters
    ----------
    track : HarmonicTrack
    harmonic : int
        n in 2 .. n_harmonics.

    Returns
    -------
    ScalingFit
        NaN exponent when fewer than 3 blocks or no amplitude variation.
    """
    if not 2 <= harmonic <= track.harmonics.shape[1]:
        raise ValueError(f"harmonic must be in [2, {track.harmonics.shape[1]}], got {harmonic}")
    la = np.log(track.amplitude)
    ln = np.log(np.abs(track.harmonics[:, harmonic - 1]))
    span = float(la.max() - la.min()) if la.size else 0.0
    if la.size < 3 or span <= 0:
        return ScalingFit(harmonic, math.nan, math.nan, span)
    design = np.column_stack([np.ones_like(la), la])
    coef, *_ = np.linalg.lstsq(design, ln, rcond=None)
    resid = ln - design @ coef
    s2 = float(resid @ resid) / max(la.size - 2, 1)
    cov = s2 * np.linalg.inv(design.T @ design)
    return ScalingFit(harmonic, float(coef[1]), float(math.sqrt(cov[1, 1])), span)
