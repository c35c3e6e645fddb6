"""Derivative estimators for sampled deflection: Savitzky-Golay, spectral, harmonic fit.

Functions do the work (`savgol_derivatives`, `spectral_derivatives`); the estimator objects
(`SavitzkyGolay`, `Spectral`, `HarmonicDerivatives`) wrap them behind one interface,
``estimator(tau, x, omega=...) -> (x_s, x', x'')``, so analyses take the strategy as an object.
All in dimensionless time ``tau = omega0 t``.
"""

from __future__ import annotations

import abc
import math
from typing import final

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from afmlearn.preprocess.harmonics import fit_harmonics

__all__ = [
    "AbstractDerivatives",
    "HarmonicDerivatives",
    "SavitzkyGolay",
    "Spectral",
    "default_window",
    "savgol_derivatives",
    "spectral_derivatives",
]

FloatArray = NDArray[np.float64]
Derivatives = tuple[FloatArray, FloatArray, FloatArray]

#: default Savitzky-Golay window as a fraction of a drive period
DEFAULT_WINDOW_FRACTION = 0.15


def default_window(samples_per_period: float, *, order: int = 3,
                   fraction: float = DEFAULT_WINDOW_FRACTION) -> int:
    """Default Savitzky-Golay window: the odd length nearest ``fraction`` of a drive period.

    Parameters
    ----------
    samples_per_period : float
        Samples per drive period, > 0.
    order : int, default 3
        Polynomial order; the window is at least ``order + 2`` (rounded up to odd).
    fraction : float, default 0.15
        Window length / drive period.

    Returns
    -------
    int
        Odd window length.

    Notes
    -----
    The window trades noise amplification in ``x''`` (a cubic fit over ``w`` samples reduces
    white noise in ``x''`` roughly as ``w^-2.5``) against smoothing of the contact, which
    lasts ~5-15 % of a tapping period. Measured on a DMT tapping trace (Q = 50, 1500 samples
    per period, 1 % noise, exact drive) with transfer-function inversion, whole-trace force
    accuracy (1 - NRMSE) vs window fraction: 0.05: -2.8, 0.08: -0.18, 0.12: 0.56, 0.15: 0.71,
    0.2: 0.76, 0.3: 0.55. On noiseless data short windows win (5 samples: 0.9997 at 1000
    samples per period). The default 0.15 is close to the best at 1 % noise while keeping the
    repulsive part (0.68 vs 0.63 at 0.2). The cubic filter's bias is large, though: on the
    noiseless trace the same inversion reaches only 0.88 (0.94 at 0.1); a quintic
    (``order=5``) with a 0.3-period window gives 0.82 at 1 % noise and 0.92 noiseless.
    Pass ``window`` / ``order`` explicitly for other noise levels.
    """
    if not (math.isfinite(samples_per_period) and samples_per_period > 0):
        raise ValueError(f"samples_per_period must be > 0, got {samples_per_period!r}")
    if not 0 < fraction <= 1:
        raise ValueError(f"fraction must be in (0, 1], got {fraction!r}")
    w = int(round(fraction * samples_per_period))
    w = max(w, order + 2)
    return w if w % 2 else w + 1


def savgol_derivatives(x: ArrayLike, dt: float, *, window: int,
                       order: int = 3) -> Derivatives:
    """Smoothed signal and first two derivatives by a Savitzky-Golay filter.

    Parameters
    ----------
    x : array-like, shape (n,)
        Uniformly sampled signal (e.g. deflection / L_ref).
    dt : float
        Sample interval (dimensionless ``omega0 / f_s``), > 0.
    window : int
        Odd window length, ``order < window <= n`` (see `default_window`).
    order : int, default 3
        Polynomial order, >= 2.

    Returns
    -------
    x_s, xd, xdd : ndarray, shape (n,)
        Smoothed ``x``, ``dx/dtau``, ``d2x/dtau2`` (scipy ``savgol_filter``, ``mode="interp"``:
        the first and last ``window // 2`` samples come from a polynomial fit to the edge
        window).
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {x.shape}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
    if isinstance(order, bool) or not isinstance(order, int | np.integer) or order < 2:
        raise ValueError(f"order must be an integer >= 2, got {order!r}")
    if isinstance(window, bool) or not isinstance(window, int | np.integer) \
            or window % 2 == 0 or not order < window <= x.size:
        raise ValueError(f"window must be an odd integer in ({order}, {x.size}], got {window!r}")
    out = tuple(scipy.signal.savgol_filter(x, window, order, deriv=d, delta=dt, mode="interp")
                for d in range(3))
    return out  # type: ignore[return-value]


def spectral_derivatives(x: ArrayLike, dt: float, *, cutoff: float | None = None) -> Derivatives:
    """Derivatives by FFT, for data that hold a whole number of periods.

    Parameters
    ----------
    x : array-like, shape (n,)
        Uniformly sampled signal that is periodic over the window (its last sample is followed
        by its first); otherwise the edges ring (Gibbs).
    dt : float
        Sample interval (dimensionless), > 0.
    cutoff : float, optional
        Low-pass: drop angular frequencies above ``cutoff`` (units of ``omega0``), e.g.
        ``(n_harmonics + 0.5) * Omega``. None keeps everything but the Nyquist bin.

    Returns
    -------
    x_s, xd, xdd : ndarray, shape (n,)
        Filtered signal and its first two derivatives with respect to ``tau``.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 4:
        raise ValueError(f"x must be 1-D with >= 4 samples, got shape {x.shape}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
    n = x.size
    spec = np.fft.rfft(x)
    w = 2 * np.pi * np.fft.rfftfreq(n, dt)
    if n % 2 == 0:
        spec[-1] = 0.0  # the Nyquist bin has no well-defined derivative
    if cutoff is not None:
        if not cutoff > 0:
            raise ValueError(f"cutoff must be > 0, got {cutoff!r}")
        spec[w > cutoff] = 0.0
    return (np.fft.irfft(spec, n), np.fft.irfft(1j * w * spec, n),
            np.fft.irfft(-(w**2) * spec, n))


class AbstractDerivatives(abc.ABC):
    """Strategy: estimate ``(x_s, x', x'')`` from samples in dimensionless time."""

    @abc.abstractmethod
    def __call__(self, tau: FloatArray, x: FloatArray, *, omega: float) -> Derivatives:
        """Smoothed ``x`` and its derivatives.

        Parameters
        ----------
        tau : ndarray, shape (n,)
            Uniform dimensionless times ``omega0 t``.
        x : ndarray, shape (n,)
            Deflection / L_ref.
        omega : float
            Drive frequency ``Omega`` (sets default windows / the series' base frequency).

        Returns
        -------
        x_s, xd, xdd : ndarray, shape (n,)
        """


@final
class SavitzkyGolay(AbstractDerivatives):
    """Savitzky-Golay derivatives (`savgol_derivatives`).

    Parameters
    ----------
    window : int, optional
        Odd window length; None: `default_window` of the samples per drive period.
    order : int, default 3
        Polynomial order.
    """

    def __init__(self, *, window: int | None = None, order: int = 3) -> None:
        self.window = window
        self.order = order

    def __call__(self, tau: FloatArray, x: FloatArray, *, omega: float) -> Derivatives:
        dt = float(tau[1] - tau[0])
        window = self.window
        if window is None:
            window = min(default_window(2 * np.pi / (omega * dt), order=self.order),
                         x.size if x.size % 2 else x.size - 1)
        return savgol_derivatives(x, dt, window=window, order=self.order)

    def __repr__(self) -> str:
        return f"SavitzkyGolay(window={self.window!r}, order={self.order!r})"


@final
class Spectral(AbstractDerivatives):
    """FFT derivatives (`spectral_derivatives`) of the longest whole number of periods.

    Samples after the last whole period are dropped from the transform and filled with NaN.

    Parameters
    ----------
    n_harmonics : int, optional
        Keep harmonics of ``Omega`` up to this order (low-pass); None keeps all.
    """

    def __init__(self, *, n_harmonics: int | None = None) -> None:
        self.n_harmonics = n_harmonics

    def __call__(self, tau: FloatArray, x: FloatArray, *, omega: float) -> Derivatives:
        dt = float(tau[1] - tau[0])
        spp = 2 * np.pi / (omega * dt)
        periods = int(x.size // spp)
        m = int(round(periods * spp)) if periods else x.size
        m = min(m, x.size)
        cutoff = None if self.n_harmonics is None else (self.n_harmonics + 0.5) * omega
        parts = spectral_derivatives(x[:m], dt, cutoff=cutoff)
        out = []
        for p in parts:
            full = np.full(x.size, np.nan)
            full[:m] = p
            out.append(full)
        return out[0], out[1], out[2]

    def __repr__(self) -> str:
        return f"Spectral(n_harmonics={self.n_harmonics!r})"


@final
class HarmonicDerivatives(AbstractDerivatives):
    """Analytic derivatives of a harmonic fit to all samples (`fit_harmonics`), periodic data.

    Parameters
    ----------
    n_harmonics : int, optional
        None: automatic (noise-floor test of `fit_harmonics`).
    max_harmonics : int, default 100
        Upper bound of the automatic choice.
    period_multiple : int, default 1
        Subharmonic order.
    """

    def __init__(self, *, n_harmonics: int | None = None, max_harmonics: int = 100,
                 period_multiple: int = 1) -> None:
        self.n_harmonics = n_harmonics
        self.max_harmonics = max_harmonics
        self.period_multiple = period_multiple

    def __call__(self, tau: FloatArray, x: FloatArray, *, omega: float) -> Derivatives:
        fit = fit_harmonics(tau, x, omega, n_harmonics=self.n_harmonics,
                            max_harmonics=self.max_harmonics,
                            period_multiple=self.period_multiple)
        return fit.evaluate(tau), fit.evaluate(tau, 1), fit.evaluate(tau, 2)

    def __repr__(self) -> str:
        return (f"HarmonicDerivatives(n_harmonics={self.n_harmonics!r}, "
                f"max_harmonics={self.max_harmonics!r}, "
                f"period_multiple={self.period_multiple!r})")
