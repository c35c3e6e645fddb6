"""Diagnosis on lock-in curves alone: which cause the baseline law misses, and the gain.

Each hypothesis (``hypotheses.EXTENSIONS``) is fitted to the approach branch from the
baseline's solution. Its evidence is the change of the Bayesian information criterion with a
Gaussian likelihood of unknown variance, ``n ln(chi2_base / chi2_ext) - k ln n`` (``k`` extra
parameters, ``n`` residuals); the gain is measured on data not fitted, the retraction branch:
``1 - nrmse_ext / nrmse_base``. The cause named is the hypothesis with the largest evidence
among those with a positive held-out gain if that exceeds ``threshold``, else ``none``; its
confidence is
its BIC weight among the baseline and the candidates with a positive held-out gain (a
candidate that predicts the retraction worse than the baseline is refuted and skipped).
"""

from __future__ import annotations

import logging
import math
from typing import Any, final

import numpy as np

from afmlearn.metrics import nrmse
from simulator.lockin import LockIn

from .curve import Curve
from .dissipation import dissipated_energy
from .fit import CurveFitter, wrap_phase
from .hypotheses import EXTENSIONS, Hypothesis
from .law import CurveLaw

__all__ = ["CurveDiagnoser", "equation", "heldout_nrmse", "name_cause"]

log = logging.getLogger(__name__)

#: shares of ``max_evaluations``: the baseline's cap, the first round of extensions and the
#: second (after a baseline refit) up to these totals; the rest refines the leaders
BUDGET_SPLIT = (0.4, 0.7, 0.85)
#: extensions refined further at the end (by BIC), and their least-squares evaluations
N_LEADERS = 2
LEADER_NFEV = 40


@final
class CurveDiagnoser:
    """Fit the baseline and every hypothesis to a curve; name the cause.

    Parameters
    ----------
    hypotheses : sequence of Hypothesis
        Candidate extensions (default: one per cause).
    threshold : float
        Smallest evidence (BIC units) for naming a cause (10: "very strong" on Kass and
        Raftery's scale).
    a0_m, tip_radius_m : float
        Contact onset and nominal tip radius [m] (see :class:`CurveFitter`).
    lockin : LockIn or None
        The recording lock-in's filter.
    max_nfev : int
        Least-squares evaluations per extension fit.
    step : float
        Time step of the slow flow (dimensionless, see :class:`CurveFitter`).
    n_starts : int
        Starts of the baseline fit (see :class:`CurveFitter`).
    extension_starts : int
        Refinements of each extension, from the best points of its start grid (1; 2 did not
        rescue the far-field damping case of the tests and costs a third more).
    max_evaluations : int or None
        Cap on the forward-model evaluations of the whole diagnosis (time per curve = this
        times the cost of one evaluation), split by ``BUDGET_SPLIT``: 40 % for the baseline at
        most; the extensions share up to 70 % of the whole equally; refitting a stuck baseline
        and the extensions from it up to 85 %; the rest refines the two leading extensions.
        None: no cap.

    Attributes
    ----------
    baseline_ : CurveFitter
    fits_ : dict of str to CurveFitter
        The fitted extension per cause.
    candidates_ : list of dict
        ``cause``, ``evidence`` (BIC units), ``gain`` (held-out), ``score`` (BIC weight).
    cause_ : str
    confidence_ : float
    gain_ : float
    n_evaluations_ : int
        Forward-model evaluations spent.
    """

    def __init__(self, *, hypotheses: tuple[Hypothesis, ...] = EXTENSIONS,
                 threshold: float = 10.0, a0_m: float = 0.3e-9, tip_radius_m: float = 10e-9,
                 lockin: LockIn | None = None, max_nfev: int = 12,
                 step: float = 4.0 * math.pi, n_starts: int = 1,
                 extension_starts: int = 1, max_evaluations: int | None = None) -> None:
        if not all(isinstance(h, Hypothesis) for h in hypotheses):
            raise ValueError("hypotheses must be Hypothesis objects")
        if not (math.isfinite(threshold) and threshold >= 0.0):
            raise ValueError(f"threshold must be a finite number >= 0, got {threshold!r}")
        self.hypotheses = tuple(hypotheses)
        self.threshold = float(threshold)
        self.a0_m = a0_m
        self.tip_radius_m = tip_radius_m
        self.lockin = lockin
        self.max_nfev = int(max_nfev)
        self.step = float(step)
        self.n_starts = int(n_starts)
        if int(extension_starts) < 1:
            raise ValueError(f"extension_starts must be >= 1, got {extension_starts!r}")
        self.extension_starts = int(extension_starts)
        if max_evaluations is not None and int(max_evaluations) < 2:
            raise ValueError(f"max_evaluations must be >= 2 or None, got {max_evaluations!r}")
        self.max_evaluations = None if max_evaluations is None else int(max_evaluations)

    def fit(self, curve: Curve) -> CurveDiagnoser:
        """Fit on the approach (``segment == 0``), measure on the retraction."""
        opts = {"a0_m": self.a0_m, "tip_radius_m": self.tip_radius_m, "lockin": self.lockin,
                "step": self.step}
        fit_mask = curve.segment == 0
        held = curve.segment == 1
        self.curve_ = curve
        budget = self.max_evaluations
        self.baseline_ = CurveFitter(
            n_starts=self.n_starts,
            max_evaluations=None if budget is None else int(BUDGET_SPLIT[0] * budget),
            **opts).fit(curve, mask=fit_mask)
        spent = self.baseline_.n_evaluations_
        self.fits_: dict[str, CurveFitter] = {}
        # each extension's share of a round grows with its parameters: a start scan is the
        # product of their starting values and an iteration costs one evaluation per
        # parameter (equal shares left the damping fit's 5 parameters ~10 evaluations beyond
        # its 144 starts, refined in three far basins: nothing refined on Asylum AZ_0170)
        weights = [len(h.parameters) for h in self.hypotheses]
        for round_ in range(2):
            for i, h in enumerate(self.hypotheses):
                # the first round may spend up to 70 % of the budget, the second one (only
                # when the baseline was stuck) up to 85 %; the rest refines the leaders
                cap = (None if budget is None
                       else int(BUDGET_SPLIT[1 + round_] * budget) - spent)
                share = (None if cap is None
                         else max(1, cap * weights[i] // sum(weights[i:])))
                f = CurveFitter(hypothesis=h, start=self.baseline_.values_,
                                max_nfev=self.max_nfev, max_evaluations=share,
                                n_starts=self.extension_starts, **opts).fit(curve, mask=fit_mask)
                spent += f.n_evaluations_
                old = self.fits_.get(h.cause)
                if old is None or f.chi2_ < old.chi2_:
                    self.fits_[h.cause] = f
            if round_ == 1 or not self.fits_:
                break
            # an extension started from the baseline may have left the baseline's local
            # minimum (the jump makes the cost rough) rather than needed its term: refit the
            # baseline from the best extension's solution without the term; if that is better,
            # the evidence is measured against it and every extension is refitted from it
            # (keeping each one's better fit)
            best = min(self.fits_.values(), key=lambda f: f.chi2_)
            if best.chi2_ >= self.baseline_.chi2_ or best.hypothesis is None:
                break
            own = {p.field for p in best.hypothesis.parameters}
            start = {k: v for k, v in best.values_.items() if k not in own}
            share = (None if budget is None
                     else max(1, (int(BUDGET_SPLIT[2] * budget) - spent) // 3))
            rebase = CurveFitter(start=start, rescales=((1.0, 1.0),), max_evaluations=share,
                                 **opts).fit(curve, mask=fit_mask)
            spent += rebase.n_evaluations_
            if rebase.chi2_ >= self.baseline_.chi2_:
                break
            log.info("baseline refitted from the %s solution: chi2 %.4g -> %.4g",
                     best.hypothesis.cause, self.baseline_.chi2_, rebase.chi2_)
            self.baseline_ = rebase
        spent += self._refine_leaders(curve, fit_mask, budget, spent, opts)
        b_chi2 = self.baseline_.chi2_
        n = self.baseline_.n_fit_
        b_held = heldout_nrmse(self.baseline_, curve, held)
        cands = []
        for h in self.hypotheses:
            f = self.fits_[h.cause]
            # the extension nests the baseline: it can never fit worse than its start
            chi2 = min(f.chi2_, b_chi2)
            k = len(h.parameters)
            evidence = n * math.log(b_chi2 / max(chi2, 1e-300)) - k * math.log(n)
            e_held = heldout_nrmse(f, curve, held)
            gain = 1.0 - e_held / b_held if b_held > 0 and np.any(held) else float("nan")
            cands.append({"cause": h.cause, "evidence": float(evidence), "gain": float(gain),
                          "heldout_nrmse": float(e_held), "chi2": float(chi2)})
        self.candidates_, self.cause_, self.confidence_, self.gain_ = name_cause(
            cands, threshold=self.threshold)
        self.baseline_heldout_ = float(b_held)
        self.n_evaluations_ = int(spent)
        return self

    def _refine_leaders(self, curve: Curve, mask: np.ndarray, budget: int | None, spent: int,
                        opts: dict) -> int:
        """Refine the ``N_LEADERS`` extensions of largest evidence further from their own
        solutions with what is left of the budget (at least ``LEADER_NFEV`` least-squares
        evaluations each without a budget); each keeps its better fit. Returns the
        evaluations spent.

        The start grids leave each extension a few least-squares iterations; the leaders'
        fits decide the cause and give the reported force (measured on a bench damping
        curve: 90 evaluations reached 2.1x the truth's chi2, 50 more reached 0.9x). A leader
        with several far basins (``CurveFitter.basins_``) is refined from each of them.
        """
        b = self.baseline_.chi2_
        ranked = sorted((f for f in self.fits_.values() if f.chi2_ < b),
                        key=lambda f: f.chi2_ * math.exp(len(f.hypothesis.parameters)
                                                         * math.log(f.n_fit_) / f.n_fit_))
        used = 0
        for i, f in enumerate(ranked[:N_LEADERS]):
            left = None if budget is None else (budget - spent - used) // (
                min(N_LEADERS, len(ranked)) - i)
            if left is not None and left < 2 * (len(f.values_) + 2):
                break
            # every far basin the extension refined (the lowest chi2 of a short refinement
            # need not be the lowest at the end), each in an equal share
            starts = [v for _, v in f.basins_] or [f.values_]
            for j, start in enumerate(starts):
                share = None if left is None else int(left // (len(starts) - j))
                if share is not None and share < 2 * (len(f.values_) + 2):
                    break
                g = CurveFitter(hypothesis=f.hypothesis, start=start, rescales=((1.0, 1.0),),
                                max_nfev=LEADER_NFEV, max_evaluations=share,
                                **opts).fit(curve, mask=mask)
                used += g.n_evaluations_
                if left is not None:
                    left -= g.n_evaluations_
                if g.chi2_ < self.fits_[f.hypothesis.cause].chi2_:
                    self.fits_[f.hypothesis.cause] = g
        return used

    @property
    def extended_(self) -> CurveFitter:
        """The fit of the named cause (the baseline when ``none``)."""
        return self.fits_.get(self.cause_, self.baseline_)

    def report(self) -> dict[str, Any]:
        """``report.json`` (``design.md`` §3 keys) plus curve-specific fields."""
        c = self.curve_
        ext = self.extended_
        e_j = self.dissipation()
        app = c.segment == 0
        return {
            "cause": self.cause_,
            "confidence": self.confidence_,
            "baseline": {"equation": equation(self.baseline_.law_, c),
                         "heldout_nrmse": self.baseline_heldout_,
                         "chi2": self.baseline_.chi2_, "n_fit": self.baseline_.n_fit_,
                         "parameters": self.baseline_.values_},
            "extended": {"equation": equation(ext.law_, c),
                         "heldout_nrmse": heldout_nrmse(ext, c, c.segment == 1),
                         "parameters": ext.values_},
            "gain": self.gain_,
            "candidates": [{"cause": k["cause"], "gain": k["gain"], "score": k["score"],
                            "evidence": f"delta BIC {k['evidence']:.1f}, held-out NRMSE "
                                        f"{k['heldout_nrmse']:.4g}"}
                           for k in self.candidates_],
            "causes": ([{"cause": self.cause_, "gain": self.gain_,
                         "evidence": self.candidates_[0]["evidence"]}]
                       if self.cause_ != "none" else []),
            "curve": {"free_amplitude_m": c.length_m, "n_points": c.n,
                      "lockin_filter": self.lockin.to_dict() if self.lockin else None,
                      "surface_offset_m": ext.offset_ * c.length_m,
                      "omega": ext.values_["omega"],
                      "dissipated_energy_ev_max": float(np.max(e_j[app])) / 1.602176634e-19,
                      "adhesion_force_n": ext.law_.adhesion * c.force_unit_n},
            "figures": [],
        }

    def dissipation(self) -> np.ndarray:
        """Measured energy loss per cycle [J], shape (m,) (Cleveland/Anczykowski formula)."""
        c = self.curve_
        return dissipated_energy(c.amplitude, c.phase, free_amplitude=1.0,
                                 free_phase=c.free_phase, quality_factor=c.quality_factor,
                                 omega=self.extended_.values_["omega"],
                                 spring_constant=1.0) * c.energy_unit_j


def name_cause(candidates: list[dict], *, threshold: float
               ) -> tuple[list[dict], str, float, float]:
    """The decision rule: which cause to name from the candidates' evidence and gain.

    Parameters
    ----------
    candidates : list of dict
        ``cause``, ``evidence`` (delta BIC against the baseline) and ``gain`` (held-out).
    threshold : float
        Smallest evidence for naming a cause.

    Returns
    -------
    scored : list of dict
        The candidates sorted by evidence, each with ``score``: its BIC weight among the
        baseline and the candidates with a positive held-out gain (a candidate that predicts
        the retraction worse than the baseline is refuted: weight 0, never named).
    cause : str
        The eligible candidate with the largest evidence if that exceeds ``threshold``, else
        ``none``.
    confidence : float
        The named cause's weight (the baseline's for ``none``).
    gain : float
        The named cause's held-out gain (0 for ``none``).
    """
    scored = sorted((dict(c) for c in candidates), key=lambda c: c["evidence"], reverse=True)
    eligible = [c for c in scored if not (c["gain"] <= 0.0)]
    ev = np.array([0.0] + [c["evidence"] for c in eligible])
    w = np.exp(0.5 * (ev - ev.max()))
    w /= w.sum()
    for c in scored:
        c["score"] = 0.0
    for c, wi in zip(eligible, w[1:], strict=True):
        c["score"] = float(wi)
    if eligible and eligible[0]["evidence"] > threshold:
        best = eligible[0]
        return scored, best["cause"], best["score"], float(best["gain"])
    return scored, "none", float(w[0]), 0.0


def heldout_nrmse(fit: CurveFitter, curve: Curve, mask: np.ndarray) -> float:
    """Mean of the amplitude and phase NRMSE on the points ``mask``.

    ``design.md`` §4 NRMSE with fixed scales: the free amplitude for the amplitude and
    ``pi/2`` (free resonance to full repulsion) for the phase, so that a curve in which the
    tip never meets the surface (flat data, a tiny range) gets a comparable number.
    """
    if not np.any(mask):
        return float("nan")
    a, p = fit.predict(curve)
    dp = wrap_phase(p - curve.phase)
    return 0.5 * (nrmse(a[mask], curve.amplitude[mask], scale=1.0)
                  + nrmse(curve.phase[mask] + dp[mask], curve.phase[mask], scale=np.pi / 2))


def equation(law: CurveLaw, curve: Curve) -> str:
    """The fitted law in SI: nN and nm."""
    fu = curve.force_unit_n * 1e9
    lu = curve.length_m * 1e9
    a0 = law.a0 * lu
    parts = [f"F = -{law.vdw * fu * lu**2:.4g}/z^2 (z > a0 = {a0:.3g} nm)",
             f"-{law.adhesion * fu:.4g} + {law.stiffness * fu / lu**law.exponent:.4g} "
             f"d^{law.exponent:.3g} (contact)"]
    if law.visco:
        parts.append(f"+ {law.visco * fu / lu**0.5:.4g} sqrt(d) d' (d' per unit omega0 t)")
    if law.damping:
        parts.append(f"- {law.damping * fu:.4g} exp(-z/{law.decay_length * lu:.3g}) z'")
    if law.far_damping:
        parts.append(f"- {law.far_damping * fu:.4g} exp(-z/{law.far_decay_length * lu:.3g}) z'")
    if law.electrostatic:
        parts.append(f"- {law.electrostatic * fu * lu**2:.4g}/(z (z + "
                     f"{law.radius * lu:.3g}))")
    if law.neck:
        parts.append(f"neck to z = a0 + {law.neck * lu:.3g} nm on retraction")
    return "; ".join(parts) + "  [nN, nm]"
