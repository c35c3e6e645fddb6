"""Noise models of an averaged spectrum: the objective a spectrum fit minimises.

`GammaLikelihood` is the right one: a periodogram bin of Gaussian data is ``E chi^2_2 / 2``;
the mean of ``nu`` independent ones is Gamma distributed with shape ``nu`` and mean ``E``, so
the negative log-likelihood is ``nu sum(P/E + ln E)`` (maximum likelihood; Whittle 1953;
for AFM thermal spectra e.g. Hutter & Bechhoefer 1993 use least squares instead).
`AmplitudeLeastSquares` is what a plain curve fit of the amplitude spectral density does
(kept to compare, and to reproduce vendor fits).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import final

import numpy as np
from numpy.typing import NDArray

__all__ = ["AmplitudeLeastSquares", "GammaLikelihood", "NoiseModel", "PowerLeastSquares"]

FloatArray = NDArray[np.float64]


class NoiseModel(ABC):
    """Objective and parameter covariance of a spectrum fit (hook: `_terms`)."""

    @abstractmethod
    def _terms(self, observed: FloatArray, expected: FloatArray,
               n_averages: float) -> tuple[FloatArray, FloatArray]:
        """Per-bin ``(objective terms, Fisher weights)``: the objective is their sum; the
        Fisher information is ``J^T diag(weights) J`` for the Jacobian ``J = dE/dtheta``."""

    def objective(self, observed: FloatArray, expected: FloatArray, n_averages: float) -> float:
        """Value to minimise (a negative log-likelihood up to a constant)."""
        return float(np.sum(self._terms(observed, expected, n_averages)[0]))

    def covariance(self, jacobian: FloatArray, observed: FloatArray, expected: FloatArray,
                   n_averages: float, *, correlation: tuple[float, ...] = (1.0,)) -> FloatArray:
        """Parameter covariance, shape (p, p), for the Jacobian ``dE/dtheta`` of shape
        (n_bins, p).

        Sandwich form ``I^-1 M I^-1`` with the Fisher information ``I = G^T G``
        (``G_k = sqrt(w_k) dE_k/dtheta``) and ``M = sum_kl rho_|k-l| G_k G_l^T`` for bins whose
        noise is correlated with coefficients ``correlation = (1, rho_1, rho_2, ...)``
        (`windows.bin_correlation`); with independent bins ``M = I`` and this is ``I^-1``.
        """
        weights = self._terms(observed, expected, n_averages)[1]
        g = np.sqrt(weights)[:, None] * jacobian
        info = g.T @ g
        meat = info.copy()
        for lag, rho in enumerate(correlation[1:], start=1):
            if lag < g.shape[0] and rho != 0:
                cross = g[:-lag].T @ g[lag:]
                meat += rho * (cross + cross.T)
        inv = np.linalg.inv(info)
        return inv @ meat @ inv


@final
class GammaLikelihood(NoiseModel):
    """Maximum likelihood for an average of ``n_averages`` independent periodograms."""

    def _terms(self, observed: FloatArray, expected: FloatArray,
               n_averages: float) -> tuple[FloatArray, FloatArray]:
        return n_averages * (observed / expected + np.log(expected)), n_averages / expected**2

    def __repr__(self) -> str:
        return "GammaLikelihood()"


@final
class AmplitudeLeastSquares(NoiseModel):
    """Unweighted least squares on ``sqrt(PSD)`` (a plain curve fit of the ASD); its
    covariance uses the residual variance (Gauss-Newton)."""

    def _terms(self, observed: FloatArray, expected: FloatArray,
               n_averages: float) -> tuple[FloatArray, FloatArray]:
        resid = np.sqrt(observed) - np.sqrt(expected)
        scale = max(float(np.mean(observed)), 1e-300)  # fixed scale: objective O(1) per bin
        sigma2 = max(float(np.mean(resid**2)), 1e-300)
        # d sqrt(E)/dE = 1 / (2 sqrt(E)): Gauss-Newton weights on dE/dtheta
        return resid**2 / scale, 1.0 / (4.0 * expected * sigma2)

    def __repr__(self) -> str:
        return "AmplitudeLeastSquares()"


@final
class PowerLeastSquares(NoiseModel):
    """Unweighted least squares on the PSD itself (weights the top of the peak; reproduces
    the Nanosurf software's fitted curve to 0.7 % in Q); Gauss-Newton covariance."""

    def _terms(self, observed: FloatArray, expected: FloatArray,
               n_averages: float) -> tuple[FloatArray, FloatArray]:
        scale = max(float(np.mean(observed)), 1e-300)
        resid = (observed - expected) / scale
        sigma2 = max(float(np.mean(resid**2)), 1e-300)
        return resid**2, np.full(expected.shape, 1.0 / (sigma2 * scale**2))

    def __repr__(self) -> str:
        return "PowerLeastSquares()"
