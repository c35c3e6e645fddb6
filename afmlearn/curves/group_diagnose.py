"""Joint diagnosis of a group of lock-in curves of one tip: one law for all curves, the cause
named by evidence, the gain measured on a curve left out of the fit.

The baseline and every hypothesis are fitted jointly to the approaches of the N curves
(:class:`GroupFitter`); the evidence is the single-curve diagnosis' BIC difference over all
residuals, ``n ln(chi2_base / chi2_ext) - k ln n`` (``k``: the hypothesis' shared parameters,
plus one drift per curve for ``drift``). A stuck baseline is refitted from the best extension's
solution without its terms (as :class:`CurveDiagnoser` does). The gain is measured on data not
fitted: leave-one-curve-out -- the law is refitted on the other N - 1 curves (from the joint
solution), the left-out curve's nuisances (surface position, drive frequency, drift) are fitted
on its approach with the law held fixed, and the whole left-out curve (approach and
retraction) is scored; ``gain`` is the median over the N folds of ``1 - nrmse_ext / nrmse_base``
(one fold whose refit failed does not decide).
A hysteretic cause (:attr:`Hypothesis.hysteretic`, the adhesion neck) is tested on the
retraction of the joint fit instead: the retraction is not fitted, and it is where the neck
acts, while a left-out curve that does not reach the surface tests only the shared attraction
(session 8: the neck groups refuted by the left-out gain had retraction gains +0.07 and +0.13;
the 8 nm fold lost 0.2-4 %, the 26 nm fold -- 0.5 nm indentation -- lost 0-8 %).
Leaving out is done for the candidates that can be named (evidence above the threshold; the
others get the retraction gain of the joint fit, which cannot change the named cause). The
decision rule is the single-curve one (:func:`afmlearn.curves.diagnose.name_cause`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any, final

import numpy as np

from simulator.lockin import LockIn

from .curve import Curve
from .diagnose import CurveDiagnoser, equation, heldout_nrmse, name_cause
from .fit import OFFSET, OMEGA
from .group import GroupFitter, group_length
from .hypotheses import DRIFT, EXTENSIONS, FREE_SCALE, Hypothesis
from .transfer import rescale_law

__all__ = ["GroupDiagnoser", "curve_nrmse", "starts_from_singles"]

log = logging.getLogger(__name__)


@final
class GroupDiagnoser:
    """Fit the baseline and every hypothesis jointly to N curves of one tip; name the cause.

    Parameters
    ----------
    hypotheses : sequence of Hypothesis
        Candidate extensions (default: one per cause).
    threshold : float
        Smallest evidence (BIC units) for naming a cause.
    a0_m, tip_radius_m : float
        Contact onset and nominal tip radius [m] (fixed).
    lockin : LockIn or None
        The recording filter of every curve (``fit(lockins=...)`` overrides per curve).
    max_nfev : int
        Least-squares iterations of each joint refinement.
    step : float
        Slow-flow time step (dimensionless).
    max_evaluations : int or None
        Cap on curve evaluations of the whole diagnosis: the baseline up to a third, the
        extensions share up to 60 % of the whole (75 % with the refit of a stuck baseline and
        its second round), the rest is shared by the leave-one-out folds. None: no cap.
    leave_one_out : bool
        Measure the gain on left-out curves (needs N >= 2); False: the joint fit's retraction.
    free_scale : bool
        Fit each curve's free-amplitude scale in every joint fit (:class:`GroupFitter`): a
        ramp that starts within reach of a long-range force does not start free.

    Attributes
    ----------
    baseline_ : GroupFitter
    fits_ : dict of str to GroupFitter
    candidates_ : list of dict
        ``cause``, ``evidence``, ``gain`` (leave-one-out where measured, else retraction),
        ``gain_retraction``, ``gain_loo`` (or None), ``score``.
    cause_, confidence_, gain_ : as :class:`CurveDiagnoser`
    loo_ : dict
        Per cause (and ``none``): the left-out curves' whole-curve NRMSE, one per fold.
    n_evaluations_ : int
    """

    def __init__(self, *, hypotheses: tuple[Hypothesis, ...] = EXTENSIONS,
                 threshold: float = 10.0, a0_m: float = 0.3e-9, tip_radius_m: float = 10e-9,
                 lockin: LockIn | None = None, max_nfev: int = 12,
                 step: float = 4.0 * math.pi, max_evaluations: int | None = None,
                 leave_one_out: bool = True, free_scale: bool = True) -> None:
        if not all(isinstance(h, Hypothesis) for h in hypotheses):
            raise ValueError("hypotheses must be Hypothesis objects")
        if not (math.isfinite(threshold) and threshold >= 0.0):
            raise ValueError(f"threshold must be a finite number >= 0, got {threshold!r}")
        if max_evaluations is not None and int(max_evaluations) < 10:
            raise ValueError(f"max_evaluations must be >= 10 or None, got {max_evaluations!r}")
        self.hypotheses = tuple(hypotheses)
        self.threshold = float(threshold)
        self.a0_m = float(a0_m)
        self.tip_radius_m = float(tip_radius_m)
        self.lockin = lockin
        self.max_nfev = int(max_nfev)
        self.step = float(step)
        self.max_evaluations = None if max_evaluations is None else int(max_evaluations)
        self.leave_one_out = bool(leave_one_out)
        self.free_scale = bool(free_scale)

    def _opts(self, lockins: list[LockIn | None]) -> dict[str, Any]:
        return {"a0_m": self.a0_m, "tip_radius_m": self.tip_radius_m, "lockins": lockins,
                "step": self.step, "free_scale": self.free_scale}

    def _cap(self, fraction: float) -> int | None:
        if self.max_evaluations is None:
            return None
        return max(1, int(fraction * self.max_evaluations) - self._spent)

    def fit(self, curves: Sequence[Curve], *,
            lockins: Sequence[LockIn | None] | None = None,
            extra_starts: dict[str, list[dict]] | None = None) -> GroupDiagnoser:
        """Diagnose the group ``curves`` (one lever and tip; fitted on the approaches).

        Parameters
        ----------
        curves : sequence of Curve
        lockins : sequence of LockIn or None, optional
            Per-curve filters (default: ``lockin`` for every curve).
        extra_starts : dict, optional
            Per cause, further joint starts (``GroupFitter.values_`` form), e.g. from
            single-curve fits.
        """
        curves = list(curves)
        lk = list(lockins) if lockins is not None else [self.lockin] * len(curves)
        opts = self._opts(lk)
        extra = extra_starts or {}
        self.curves_ = curves
        self.lockins_ = lk
        self._spent = 0
        log.info("group of %d curves: baseline", len(curves))
        self.baseline_ = GroupFitter(max_nfev=max(self.max_nfev, 20),
                                     extra_starts=extra.get("none", ()),
                                     max_evaluations=self._cap(0.2), **opts).fit(curves)
        self._spent += self.baseline_.n_evaluations_
        self.fits_: dict[str, GroupFitter] = {}
        for round_ in range(2):
            for i, h in enumerate(self.hypotheses):
                cap = self._cap(0.6 if round_ == 0 else 0.75)
                share = None if cap is None else max(1, cap // (len(self.hypotheses) - i))
                f = GroupFitter(hypothesis=h, start=self.baseline_.values_,
                                extra_starts=extra.get(h.cause, ()) if round_ == 0 else (),
                                max_nfev=self.max_nfev, max_evaluations=share,
                                rescan=h.long_range, **opts).fit(curves)
                self._spent += f.n_evaluations_
                log.info("group %s: chi2 %.5g (baseline %.5g)", h.cause, f.chi2_,
                         self.baseline_.chi2_)
                old = self.fits_.get(h.cause)
                if old is None or f.chi2_ < old.chi2_:
                    self.fits_[h.cause] = f
            if round_ == 1 or not self.fits_:
                break
            best = min(self.fits_.values(), key=lambda f: f.chi2_)
            if best.chi2_ >= self.baseline_.chi2_ or best.hypothesis is None:
                break
            own = {p.field for p in best.hypothesis.parameters}
            start = {"law": {k: v for k, v in best.values_["law"].items() if k not in own},
                     "length_m": best.length_m_,
                     "curves": [{k: v for k, v in c.items() if k not in own}
                                for c in best.values_["curves"]]}
            rebase = GroupFitter(start=start, rescales=((1.0, 1.0),), max_nfev=self.max_nfev,
                                 max_evaluations=self._cap(0.65), **opts).fit(curves)
            self._spent += rebase.n_evaluations_
            if rebase.chi2_ >= self.baseline_.chi2_ * (1.0 - 1e-4):
                break
            log.info("group baseline refitted from the %s solution: chi2 %.5g -> %.5g",
                     best.hypothesis.cause, self.baseline_.chi2_, rebase.chi2_)
            self.baseline_ = rebase
        b = self.baseline_
        n = b.n_fit_
        b_ret = retraction_nrmse(b)
        cands = []
        for h in self.hypotheses:
            f = self.fits_[h.cause]
            chi2 = min(f.chi2_, b.chi2_)
            # the free-amplitude scale is not fitted jointly (GroupFitter)
            k = sum(len(curves) if p.field == DRIFT else 1 for p in h.parameters
                    if p.field != FREE_SCALE)
            evidence = n * math.log(b.chi2_ / max(chi2, 1e-300)) - k * math.log(n)
            # an extension that fits no better than the baseline is the baseline (it nests it)
            e_ret = retraction_nrmse(f) if f.chi2_ < b.chi2_ else b_ret
            cands.append({"cause": h.cause, "evidence": float(evidence),
                          "gain_retraction": 1.0 - e_ret / b_ret if b_ret > 0 else math.nan,
                          "chi2": float(chi2), "n_parameters": k, "gain_loo": None})
        self.loo_: dict[str, list[float]] = {}
        if self.leave_one_out and len(curves) >= 2:
            # a hysteretic cause keeps its retraction gain (module docstring)
            hyst = {h.cause for h in self.hypotheses if h.hysteretic}
            todo = [c for c in cands if c["evidence"] > self.threshold
                    and c["cause"] not in hyst]
            if todo:
                if self.max_evaluations is not None:
                    # what is left, per fold and law (a refit and a prediction each)
                    self._fold_cap = max(10 * len(curves), (self.max_evaluations - self._spent)
                                         // (2 * len(curves) * (1 + len(todo))))
                self.loo_["none"] = self._loo(b, None)
                base_loo = np.array(self.loo_["none"])
                for c in todo:
                    h = next(h for h in self.hypotheses if h.cause == c["cause"])
                    self.loo_[h.cause] = self._loo(self.fits_[h.cause], h)
                    # the median over the folds: one fold whose refit failed (either law)
                    # does not decide
                    c["gain_loo"] = float(np.median(1.0 - np.array(self.loo_[h.cause])
                                                    / np.maximum(base_loo, 1e-300)))
                    log.info("group %s: leave-one-out gain %.3f", h.cause, c["gain_loo"])
        for c in cands:
            c["gain"] = c["gain_loo"] if c["gain_loo"] is not None else c["gain_retraction"]
            c["heldout_nrmse"] = (float(np.mean(self.loo_[c["cause"]]))
                                  if c["cause"] in self.loo_ else math.nan)
        self.candidates_, self.cause_, self.confidence_, self.gain_ = name_cause(
            cands, threshold=self.threshold)
        self.baseline_retraction_ = float(b_ret)
        self.n_evaluations_ = int(self._spent)
        return self

    def _loo(self, full: GroupFitter, hypothesis: Hypothesis | None) -> list[float]:
        """Whole-curve NRMSE of each curve predicted by the law fitted on the others."""
        out = []
        curves, lk = self.curves_, self.lockins_
        n = len(curves)
        for i in range(n):
            keep = [j for j in range(n) if j != i]
            start = {"law": full.values_["law"], "length_m": full.length_m_,
                     "curves": [full.values_["curves"][j] for j in keep]}
            cap = None if self.max_evaluations is None else self._fold_cap
            fit = GroupFitter(hypothesis=hypothesis, start=start, rescales=((1.0, 1.0),),
                              max_nfev=self.max_nfev, max_evaluations=cap,
                              **self._opts([lk[j] for j in keep])).fit([curves[j]
                                                                        for j in keep])
            self._spent += fit.n_evaluations_
            drift = None if hypothesis is None or not any(
                p.field == DRIFT for p in hypothesis.parameters) else hypothesis
            pred = GroupFitter(hypothesis=drift, fixed_law=(fit.law_, fit.length_m_),
                               max_nfev=self.max_nfev, max_evaluations=cap,
                               **self._opts([lk[i]])).fit([curves[i]])
            self._spent += pred.n_evaluations_
            out.append(curve_nrmse(pred, 0))
            log.info("left out curve %d (%s): whole-curve NRMSE %.4g", i,
                     hypothesis.cause if hypothesis else "baseline", out[-1])
        return out

    @property
    def extended_(self) -> GroupFitter:
        """The joint fit of the named cause (the baseline when ``none``)."""
        return self.fits_.get(self.cause_, self.baseline_)

    def report(self) -> dict[str, Any]:
        """``report.json`` (``design.md`` section 3 keys) plus ``group``: per-curve figures."""
        b, ext = self.baseline_, self.extended_
        c0 = self.curves_[0]
        ref = _unit_curve(c0, b.length_m_)
        per_curve = []
        for i, c in enumerate(self.curves_):
            per_curve.append({
                "free_amplitude_m": c.length_m, "n_points": c.n,
                "chi2_baseline": b.chi2_curves_[i], "chi2_extended": ext.chi2_curves_[i],
                "retraction_nrmse_baseline": curve_nrmse(b, i, c.segment == 1),
                "retraction_nrmse_extended": curve_nrmse(ext, i, c.segment == 1),
                "loo_nrmse_baseline": _at(self.loo_.get("none"), i),
                "loo_nrmse_extended": _at(self.loo_.get(self.cause_), i),
                "surface_offset_m": ext.values_["curves"][i]["offset"] * c.length_m,
                "nuisances": ext.values_["curves"][i]})
        named = self.candidates_[0] if self.cause_ != "none" else None
        return {
            "cause": self.cause_,
            "confidence": self.confidence_,
            "baseline": {"equation": equation(b.law_, ref),
                         "heldout_nrmse": float(np.mean(self.loo_["none"]))
                         if "none" in self.loo_ else self.baseline_retraction_,
                         "chi2": b.chi2_, "n_fit": b.n_fit_, "parameters": b.values_},
            "extended": {"equation": equation(ext.law_, ref),
                         "heldout_nrmse": float(np.mean(self.loo_[self.cause_]))
                         if self.cause_ in self.loo_ else retraction_nrmse(ext),
                         "chi2": ext.chi2_, "parameters": ext.values_},
            "gain": self.gain_,
            "heldout": ("leave-one-curve-out: whole left-out curve, law fitted on the others"
                        if self.loo_ else "retraction of the fitted curves"),
            "candidates": [{"cause": k["cause"], "gain": k["gain"], "score": k["score"],
                            "evidence": f"delta BIC {k['evidence']:.1f}, leave-one-out gain "
                                        f"{_fmt(k['gain_loo'])}, retraction gain "
                                        f"{_fmt(k['gain_retraction'])}"}
                           for k in self.candidates_],
            "causes": ([{"cause": self.cause_, "gain": self.gain_,
                         "evidence": named["evidence"]}] if named else []),
            "group": {"n_curves": len(self.curves_), "length_m": b.length_m_,
                      "n_evaluations": self.n_evaluations_, "curves": per_curve},
            "figures": [],
        }


def starts_from_singles(diagnosers: Sequence[CurveDiagnoser]) -> dict[str, list[dict]]:
    """Joint starts from single-curve diagnoses of the same curves (``extra_starts`` of
    :meth:`GroupDiagnoser.fit`): per cause, each curve's fitted law rescaled to the group
    unit, with every curve's own fitted nuisances of that cause."""
    curves = [d.curve_ for d in diagnosers]
    length = group_length(curves)
    out: dict[str, list[dict]] = {}
    causes = ["none"] + [c for c in diagnosers[0].fits_ if all(c in d.fits_ for d in diagnosers)]
    for cause in causes:
        fits = [d.baseline_ if cause == "none" else d.fits_[cause] for d in diagnosers]
        nuis = [{k: v for k, v in f.values_.items() if k in (OFFSET, OMEGA, DRIFT)}
                for f in fits]
        starts = []
        for f, c in zip(fits, curves, strict=True):
            law = rescale_law(f.law_, c.length_m / length)
            # the free-amplitude scale is a single-curve nuisance the joint fit holds at 1
            starts.append({"law": {k: getattr(law, k) for k in f.values_
                                   if k not in (OFFSET, OMEGA, DRIFT, FREE_SCALE)},
                           "curves": nuis,
                           "length_m": length})
        out[cause] = starts
    return out


def _at(values: list[float] | None, i: int) -> float | None:
    return None if values is None else float(values[i])


def _fmt(v: float | None) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.3f}"


def _unit_curve(curve: Curve, length_m: float) -> Curve:
    """``curve``'s scales with another length unit (for :func:`equation` in the group unit)."""
    r = curve.length_m / length_m
    return Curve(tau=curve.tau, amplitude=curve.amplitude * r, phase=curve.phase,
                 z_piezo=curve.z_piezo * r, segment=curve.segment,
                 quality_factor=curve.quality_factor,
                 spring_constant_n_per_m=curve.spring_constant_n_per_m,
                 resonance_frequency_hz=curve.resonance_frequency_hz, length_m=length_m,
                 drive_frequency_hz=curve.drive_frequency_hz)


class _Member:
    """Curve ``i`` of a joint fit as :func:`heldout_nrmse` wants it: ``predict(curve)``."""

    def __init__(self, fit: GroupFitter, i: int) -> None:
        self.fit, self.i = fit, i

    def predict(self, curve: Curve):
        return self.fit.predict(self.i, curve)


def curve_nrmse(fit: GroupFitter, i: int, mask: np.ndarray | None = None) -> float:
    """:func:`afmlearn.curves.diagnose.heldout_nrmse` of curve ``i`` of a joint fit on
    ``mask`` (default: the whole curve)."""
    c = fit.curves_[i]
    m = np.ones(c.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    return heldout_nrmse(_Member(fit, i), c, m)


def retraction_nrmse(fit: GroupFitter) -> float:
    """Mean over the curves of the retraction NRMSE of a joint fit (NaN without retractions)."""
    vals = [curve_nrmse(fit, i, c.segment == 1) for i, c in enumerate(fit.curves_)]
    vals = [v for v in vals if math.isfinite(v)]
    return float(np.mean(vals)) if vals else math.nan
