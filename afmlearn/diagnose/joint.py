"""`JointBalance`: one model, many observations, on the whitened harmonic balance.

The observations of an experiment share the cantilever and the tip--sample law: ``K, D, B``,
the force coefficients, ``a0`` and every extension parameter are common; each observation has
its own rest gap (known) and drive phase ``phi_i`` (a nuisance: fitted, with a Gaussian prior
when the file records it). The whitened rows of every observation (:class:`HarmonicBalance`,
each in units of its own orbit noise) are stacked and solved together; the calibration priors
enter once, the phase priors once per observation.

Several free amplitudes. Observations recorded at different free amplitudes (files of one tip
combined) were driven with different amplitudes: each *drive group* (:func:`~afmlearn.
diagnose.observation.drive_groups`) has its own ``B``, still a linear coefficient of the
variable projection, with its own calibration prior ``B_g = F_c,g``. The coefficient vector
keeps the one-group layout and appends the other groups' drives::

    coef = [K, D, B_0, c_1 .. c_m, B_1 .. B_{G-1}]

so code that reads ``coef[:3]`` and the force coefficients ``coef[3:3 + m]`` is unchanged,
and one group is exactly today's problem. :meth:`JointBalance.observation_coef` gives the
one-observation layout ``[K, D, B_g, c]`` of any observation. A subset (held-out fold) keeps
every group's column: a group with no observation left in it is held at its calibration prior
(its ``F_c``; with no free data at the value it starts from), which is how a whole held-out
free amplitude is predicted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import final

import numpy as np
from numpy.typing import NDArray

from afmlearn.preprocess.phase import wrap_angle

from .balance import N_LEVER, HarmonicBalance, Solution, bounded_lstsq
from .spec import ModelSpec

__all__ = ["JointBalance", "PhasePrior", "wrap"]

FloatArray = NDArray[np.float64]

#: (mean, standard deviation) of a recorded drive phase in the model's convention [rad]
PhasePrior = tuple[float, float]


wrap = wrap_angle  # angle(s) wrapped to (-pi, pi]: the one helper in afmlearn.preprocess

#: offsets of :meth:`JointBalance.best_phase`'s grid around its start [rad]
_PHASE_GRID = np.linspace(-np.pi, np.pi, 64, endpoint=False)


@final
class JointBalance:
    """Stacked whitened harmonic balance of several observations with one force law.

    Parameters
    ----------
    balances : sequence of HarmonicBalance
        One per observation (same calibration ``Q``; within a drive group the same drive
        amplitude ``F_c``, its orbits' ``drive_amplitude``).
    phase_priors : sequence of PhasePrior or None
        Per observation: the recorded drive phase and its standard deviation, or None.
    groups : sequence of int, optional
        Drive group of each observation, integers ``0 .. G-1`` each used at least once
        (:func:`~afmlearn.diagnose.observation.drive_groups`); default: one group (one
        ``B`` for every observation, as before several free amplitudes were fitted).
    """

    def __init__(self, balances: Sequence[HarmonicBalance],
                 phase_priors: Sequence[PhasePrior | None], *,
                 groups: Sequence[int] | None = None) -> None:
        assert len(balances) == len(phase_priors) and len(balances) > 0
        self.balances = list(balances)
        self.phase_priors = list(phase_priors)
        if groups is None:
            groups = [0] * len(self.balances)
        groups = [int(g) for g in groups]
        if len(groups) != len(self.balances) or sorted(set(groups)) != list(
                range(max(groups) + 1)):
            raise ValueError(f"groups must give each of the {len(self.balances)} observations "
                             f"a group 0 .. G-1, each used, got {groups!r}")
        self.groups = groups
        #: each group's calibrated drive amplitude F_c [k L_ref] (None: not calibrated)
        self.group_drives: list[float | None] = [
            self.balances[groups.index(g)].orbit.drive_amplitude
            for g in range(max(groups) + 1)]
        #: structures rejected so far because their columns were not finite on the orbits
        #: (:func:`~afmlearn.diagnose.balance.bounded_lstsq`; chi2 inf)
        self.n_rejected = 0

    @property
    def n_obs(self) -> int:
        return len(self.balances)

    @property
    def n_groups(self) -> int:
        return len(self.group_drives)

    def subset(self, indices: Sequence[int]) -> JointBalance:
        """The joint balance of some observations (for held-out folds), in the same
        coefficient layout: every drive group keeps its column and its calibration."""
        out = JointBalance([self.balances[i] for i in indices],
                           [self.phase_priors[i] for i in indices])
        out.groups = [self.groups[i] for i in indices]
        out.group_drives = list(self.group_drives)
        return out

    # ------------------------------------------------------------------ drive groups
    def drive_index(self, i: int, spec: ModelSpec) -> int:
        """Index in ``coef`` of observation ``i``'s drive amplitude ``B``."""
        g = self.groups[i]
        return 2 if g == 0 else N_LEVER + spec.n_force + g - 1

    def observation_coef(self, i: int, spec: ModelSpec, coef: FloatArray) -> FloatArray:
        """``[K, D, B_g, c_1..c_m]`` of observation ``i`` from the joint ``coef``."""
        coef = np.asarray(coef, float)
        p = N_LEVER + spec.n_force
        if self.n_groups == 1:
            return coef[:p] if coef.size != p else coef
        out = np.array(coef[:p], float)
        out[2] = coef[self.drive_index(i, spec)]
        return out

    def _group_design(self, i: int, spec: ModelSpec, A: FloatArray) -> FloatArray:
        """Observation ``i``'s design with its drive column moved to its group's."""
        if self.n_groups == 1:
            return A
        out = np.zeros((A.shape[0], A.shape[1] + self.n_groups - 1))
        out[:, : A.shape[1]] = A
        j = self.drive_index(i, spec)
        if j != 2:
            out[:, j] = A[:, 2]
            out[:, 2] = 0.0
        return out

    def _drive_box(self, g: int, hb: HarmonicBalance) -> tuple[float, float]:
        fc = self.group_drives[g]
        if fc is not None and fc > 0:
            return fc * (1 - hb.box_rel), fc * (1 + hb.box_rel)
        return 0.0, math.inf

    def phase_residual(self, phases: Sequence[float]) -> FloatArray:
        """Prior rows of the recorded phases, ``(phi_i - mean_i) / sd_i`` (wrapped)."""
        out = [wrap(p - pr[0]) / pr[1] for p, pr in zip(phases, self.phase_priors, strict=True)
               if pr is not None]
        return np.asarray(out, float)

    def bounds(self, spec: ModelSpec) -> tuple[FloatArray, FloatArray]:
        """Boxes of the joint ``coef`` (:meth:`HarmonicBalance.bounds`, one drive box per
        group around its ``F_c``)."""
        hb = self.balances[0]
        lo, hi = hb.bounds(spec)
        if self.n_groups == 1:
            return lo, hi
        boxes = [self._drive_box(g, hb) for g in range(self.n_groups)]
        lo[2], hi[2] = boxes[0]
        lo = np.concatenate([lo, [b[0] for b in boxes[1:]]])
        hi = np.concatenate([hi, [b[1] for b in boxes[1:]]])
        return lo, hi

    def prior_rows(self, p: int) -> tuple[FloatArray, FloatArray]:
        """Calibration-prior rows of the joint ``coef`` (``p`` columns): ``K``, ``D`` and one
        ``B_g = F_c,g`` row per calibrated group (sigma units)."""
        hb = self.balances[0]
        if self.n_groups == 1:
            return hb.prior_rows(p)
        P, t = hb.prior_rows(p)
        rows, targets = [P[0], P[1]], [t[0], t[1]]
        m = p - (self.n_groups - 1)             # the one-group layout's size
        for g, fc in enumerate(self.group_drives):
            if fc is not None and fc > 0:
                j = 2 if g == 0 else m + g - 1
                rows.append(np.eye(p)[j] / (hb.prior_rel * fc))
                targets.append(1.0 / hb.prior_rel)
        return np.array(rows), np.array(targets)

    def prior_residual(self, coef: FloatArray) -> FloatArray:
        """The calibration-prior rows of the residual for the joint ``coef``."""
        P, t = self.prior_rows(coef.size)
        return P @ coef - t

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
        if project and any(pr is None for pr in self.phase_priors):
            return self.polish_phases(spec, phases, values)
        blocks = [hb.design(spec, ph) for hb, ph in zip(self.balances, phases, strict=True)]
        A = np.vstack([self._group_design(i, spec, a) for i, (a, _) in enumerate(blocks)])
        b = np.concatenate([bb for _, bb in blocks])
        lo, hi = self.bounds(spec)
        coef, r = bounded_lstsq(A, b, *self.prior_rows(A.shape[1]), lo, hi)
        if not np.all(np.isfinite(r)):
            self.n_rejected += 1
        r = np.concatenate([r, self.phase_residual(phases)])
        return Solution(spec=spec, coef=coef, residual=r, chi2=float(r @ r),
                        values=tuple(values), phases=tuple(float(x) for x in phases))

    def polish_phases(self, spec: ModelSpec, phases: Sequence[float],
                      values: tuple[float, ...] = (), *, max_iter: int = 40,
                      rtol: float = 1e-10) -> Solution:
        """The drive phases minimising the stacked chi-square, the coefficients solved at
        every step (variable projection; Gauss--Newton on the phases from ``phases``).

        Needed when a phase is not recorded: alternating the linear solve with each phase's
        own exact minimisation (:meth:`best_phase`) zig-zags along the valley in which a
        phase trades against the drive amplitude, damping and force coefficients. Measured on
        a null 8-set-point series without its recorded phases: 3 alternations left chi2 at
        28,985, 1,000 at 16,851, against 16,851 in 11 Gauss--Newton evaluations here (the
        phases that the recorded ones give: 16,859). The step is the joint linearisation over
        the phases and the coefficients not on a bound; the coefficients are then re-solved
        with their bounds at the new phases (step halved until chi2 falls).
        """
        phases = [float(p) for p in phases]
        sol = self.solve(spec, phases, values)
        if not math.isfinite(sol.chi2):
            return sol
        n = self.n_obs
        for _ in range(max_iter):
            blocks = [hb.design(spec, ph) for hb, ph in zip(self.balances, phases, strict=True)]
            A = np.vstack([self._group_design(i, spec, a) for i, (a, _) in enumerate(blocks)])
            P, _t = self.prior_rows(A.shape[1])
            lo, hi = self.bounds(spec)
            c = sol.coef
            span = np.where(np.isfinite(hi - lo), hi - lo, np.abs(c) + 1.0)
            free = (c > lo + 1e-9 * span) & (c < hi - 1e-9 * span)
            rows = A.shape[0] + P.shape[0]
            Jp = np.zeros((rows + sum(pr is not None for pr in self.phase_priors), n))
            r0 = 0
            for i, (a, _) in enumerate(blocks):
                _, _, w1, w2 = self.balances[i].parts(spec)
                B = float(c[self.drive_index(i, spec)])
                Jp[r0:r0 + a.shape[0], i] = B * (math.sin(phases[i]) * w1
                                                 - math.cos(phases[i]) * w2)
                r0 += a.shape[0]
            k = rows
            for i, pr in enumerate(self.phase_priors):
                if pr is not None:
                    Jp[k, i] = 1.0 / pr[1]
                    k += 1
            Jc = np.zeros((Jp.shape[0], int(free.sum())))
            Jc[:rows] = np.vstack([A, P])[:, free]
            J = np.hstack([Jc, Jp])
            scale = np.linalg.norm(J, axis=0)
            scale[scale == 0] = 1.0
            step = np.linalg.lstsq(J / scale, -sol.residual, rcond=None)[0] / scale
            dphi = step[Jc.shape[1]:]
            improved = False
            for _h in range(12):
                trial = self.solve(spec, [p + d for p, d in zip(phases, dphi, strict=True)],
                                   values)
                if trial.chi2 < sol.chi2:
                    improved = True
                    break
                dphi = dphi / 2
            if not improved:
                break
            gain = sol.chi2 - trial.chi2
            sol, phases = trial, list(trial.phases)
            if gain <= rtol * max(sol.chi2, 1.0):
                break
        return sol

    def best_phase(self, i: int, spec: ModelSpec, coef: FloatArray, start: float) -> float:
        """Observation ``i``'s drive phase minimising its whitened rows (and its prior) for
        fixed coefficients: ``|u - B (cos phi w1 + sin phi w2)|^2``, a trigonometric
        function of one angle (grid of 64, then Newton steps from the best grid point)."""
        A0, b, w1, w2 = self.balances[i].parts(spec)
        coef = self.observation_coef(i, spec, coef)
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

        grid = start + _PHASE_GRID
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
