"""`JointBalance`: one model, many observations, on the whitened harmonic balance.

The observations of an experiment share the cantilever and the tip--sample law: ``K, D, B``,
the force coefficients, ``a0`` and every extension parameter are common; each observation has
its own rest gap (known) and drive phase ``phi_i`` (a nuisance: fitted, with a Gaussian prior
when the file records it). The whitened rows of every observation (:class:`HarmonicBalance`,
each in units of its own orbit noise) are stacked and solved together; the calibration priors
enter once, the phase priors once per observation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import final

import numpy as np
from numpy.typing import NDArray

from afmlearn.preprocess.phase import wrap_angle

from .balance import HarmonicBalance, Solution, bounded_lstsq
from .spec import ModelSpec

__all__ = ["JointBalance", "PhasePrior", "wrap"]

FloatArray = NDArray[np.float64]

#: (mean, standard deviation) of a recorded drive phase in the model's convention [rad]
PhasePrior = tuple[float, float]


wrap = wrap_angle  # angle(s) wrapped to (-pi, pi]: the one helper in afmlearn.preprocess


@final
class JointBalance:
    """Stacked whitened harmonic balance of several observations with one force law.

    Parameters
    ----------
    balances : sequence of HarmonicBalance
        One per observation (same calibration: ``Q`` and drive amplitude).
    phase_priors : sequence of PhasePrior or None
        Per observation: the recorded drive phase and its standard deviation, or None.
    """

    def __init__(self, balances: Sequence[HarmonicBalance],
                 phase_priors: Sequence[PhasePrior | None]) -> None:
        assert len(balances) == len(phase_priors) and len(balances) > 0
        self.balances = list(balances)
        self.phase_priors = list(phase_priors)
        #: structures rejected so far because their columns were not finite on the orbits
        #: (:func:`~afmlearn.diagnose.balance.bounded_lstsq`; chi2 inf)
        self.n_rejected = 0

    @property
    def n_obs(self) -> int:
        return len(self.balances)

    def subset(self, indices: Sequence[int]) -> JointBalance:
        """The joint balance of some observations (for held-out folds)."""
        return JointBalance([self.balances[i] for i in indices],
                            [self.phase_priors[i] for i in indices])

    def phase_residual(self, phases: Sequence[float]) -> FloatArray:
        """Prior rows of the recorded phases, ``(phi_i - mean_i) / sd_i`` (wrapped)."""
        out = [wrap(p - pr[0]) / pr[1] for p, pr in zip(phases, self.phase_priors, strict=True)
               if pr is not None]
        return np.asarray(out, float)

    def bounds(self, spec: ModelSpec) -> tuple[FloatArray, FloatArray]:
        return self.balances[0].bounds(spec)

    def prior_residual(self, coef: FloatArray) -> FloatArray:
        return self.balances[0].prior_residual(coef)

    def solve(self, spec: ModelSpec, phases: Sequence[float],
              values: tuple[float, ...] = (), *, project: int = 0) -> Solution:
        """Bounded linear least squares of the stacked rows, calibration and phase priors.

        ``spec``'s own drive phase is ignored; observation ``i`` uses ``phases[i]``, or, with
        ``project = m > 0``, the phases after ``m`` alternations of the linear solve with the
        exact one-dimensional minimisation of each observation's phase (:meth:`best_phase`)
        from ``phases``: a smooth function of the structure, so the outer search over
        ``a0`` and the extension's parameters needs no phase columns.
        """
        if spec.drive_phase != 0.0:
            spec = spec.replace(drive_phase=0.0)
        phases = list(phases)
        for _ in range(project):
            sol = self.solve(spec, phases, values)
            phases = [self.best_phase(i, spec, sol.coef, ph) for i, ph in enumerate(phases)]
        blocks = [hb.design(spec, ph) for hb, ph in zip(self.balances, phases, strict=True)]
        A = np.vstack([a for a, _ in blocks])
        b = np.concatenate([bb for _, bb in blocks])
        lo, hi = self.bounds(spec)
        coef, r = bounded_lstsq(A, b, *self.balances[0].prior_rows(A.shape[1]), lo, hi)
        if not np.all(np.isfinite(r)):
            self.n_rejected += 1
        r = np.concatenate([r, self.phase_residual(phases)])
        return Solution(spec=spec, coef=coef, residual=r, chi2=float(r @ r),
                        values=tuple(values), phases=tuple(float(x) for x in phases))

    def best_phase(self, i: int, spec: ModelSpec, coef: FloatArray, start: float) -> float:
        """Observation ``i``'s drive phase minimising its whitened rows (and its prior) for
        fixed coefficients: ``|u - B (cos phi w1 + sin phi w2)|^2``, a trigonometric
        function of one angle (grid of 64, then Newton steps from the best grid point)."""
        A0, b, w1, w2 = self.balances[i].parts(spec)
        u = A0 @ coef - b
        B = float(coef[2])
        a, bb = float(u @ w1), float(u @ w2)
        p, q, s = float(w1 @ w1), float(w2 @ w2), float(w1 @ w2)
        pr = self.phase_priors[i]

        def f(ph: FloatArray) -> FloatArray:
            c, sn = np.cos(ph), np.sin(ph)
            out = -2 * B * (c * a + sn * bb) + B**2 * (c * c * p + sn * sn * q + 2 * sn * c * s)
            if pr is not None:
                out = out + (wrap(ph - pr[0]) / pr[1]) ** 2
            return out

        grid = start + np.linspace(-np.pi, np.pi, 64, endpoint=False)
        ph = float(grid[int(np.argmin(f(grid)))])
        for _ in range(8):
            c, sn = math.cos(ph), math.sin(ph)
            c2, s2 = math.cos(2 * ph), math.sin(2 * ph)
            d1 = -2 * B * (-sn * a + c * bb) + B**2 * (s2 * (q - p) + 2 * c2 * s)
            d2 = -2 * B * (-c * a - sn * bb) + B**2 * (2 * c2 * (q - p) - 4 * s2 * s)
            if pr is not None:
                d1 += 2 * wrap(ph - pr[0]) / pr[1] ** 2
                d2 += 2 / pr[1] ** 2
            if d2 <= 0:
                break
            step = max(min(d1 / d2, 0.1), -0.1)
            ph -= step
            if abs(step) < 1e-10:
                break
        return ph

    def initial_phases(self, spec: ModelSpec, n_phase: int = 16) -> list[float]:
        """Drive phases for ``spec`` from each observation fitted on its own.

        Every observation's rows are solved alone at ``n_phase`` phases over the circle; the
        best is polished by alternation (:meth:`best_phase`). A recorded phase is taken as it
        is. (A relaxed joint problem with a free complex drive per observation was tried
        first: on one null record it landed in a wrong basin, held-out NRMSE 0.59.)
        """
        out = []
        for i, pr in enumerate(self.phase_priors):
            if pr is not None:
                out.append(float(pr[0]))
                continue
            one = self.subset([i])
            grid = np.linspace(-math.pi, math.pi, n_phase, endpoint=False)
            best = min((one.solve(spec, [float(ph)]) for ph in grid), key=lambda r: r.chi2)
            out.append(one.solve(spec, best.phases, project=2).phases[0])
        return out
