"""Diagnose a free (contact-less) oscillation record: which cause makes its harmonics.

`diagnose_free` runs, on a record ``y`` (any units) and its sampling rate only:

1. demodulation of the fundamental (amplitude ``A(t)``, phase ``phi(t)``; `demodulate`);
2. the baseline, a linear one-mode lever (``y = c + A cos(phi)``: no harmonics), and each
   cause as a linear extension of it (`afmlearn.freeosc.causes`), fitted on the first
   ``1 - heldout_fraction`` of the record and predicting the rest. The fundamental's state on
   the held-out span is its own demodulation (a self-oscillating lever is its own clock);
   what is predicted is everything else: offset and harmonics, from coefficients fitted on
   the first span. ``gain = 1 - NRMSE(cause) / NRMSE(baseline)`` on the held-out span
   (design.md section 4);
3. evidence independent of those fits (`afmlearn.freeosc.evidence`) on the per-block
   harmonics (`track_harmonics`); a candidate the evidence rules out physically (`_excluded`)
   is not named;
4. the cause named: the largest held-out gain, if above ``min_gain``; then every other cause
   is tested on top of it (step by step, the same held-out rule).

Nothing here needs the spring constant, the detector sensitivity or the gap: the
calibration-free quantities are ratios (``|X_n| / |X_1|``), exponents, phases and gains. The
quality factor enters only the phase of ``H(n Omega)`` in `GapModulatedForce` and
`DuffingStiffness` (high-Q limit by default).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afmlearn.freeosc.causes import (
    AbstractCause,
    AcBiasDrive,
    DetectorNonlinearity,
    DuffingStiffness,
    GapModulatedForce,
    HigherMode,
    LinearLever,
    Quantisation,
)
from afmlearn.freeosc.combined import Combined
from afmlearn.freeosc.demodulate import Demodulation, demodulate
from afmlearn.freeosc.evidence import (
    dc_coupling,
    gap_force_requirement,
    non_harmonic_peak,
    phase_lock,
    quadrature_scaling,
    quantisation_step,
    scaling_with_drift,
)
from afmlearn.freeosc.track import HarmonicTrack, track_harmonics
from afmlearn.metrics import nrmse

__all__ = ["FreeOscillationDiagnosis", "default_causes", "diagnose_free"]

logger = logging.getLogger(__name__)

#: smallest held-out gain for a cause to be named (measured on the synthetic checks: a clean
#: lever with 1 % noise and 12-bit quantisation gives |gain| < 0.01 for every cause)
MIN_GAIN = 0.05
#: a further cause is added in the step-by-step naming when it lowers the held-out NRMSE of
#: the model before it by at least this fraction
MIN_STEP_GAIN = 0.02
#: a physically required frequency drift beyond this multiple of the measured one excludes a
#: candidate (see `_excluded`)
_FREQUENCY_MARGIN = 10.0
#: an amplitude exponent this many standard errors from 0 rules out a fixed-amplitude drive
_EXPONENT_SIGMAS = 4.0
#: relative line amplitude above which a non-harmonic peak becomes a higher-mode candidate
_MODE_LINE = 1e-3


@final
@dataclass(frozen=True, eq=False)
class FreeOscillationDiagnosis:
    """Result of `diagnose_free` (``to_dict`` gives design.md section 3's report fields).

    Attributes
    ----------
    cause : str
        The named cause (``"none"`` when no cause reaches ``min_gain``).
    confidence : float
        In [0, 1]: ``1 - gain_runner_up / gain_best`` over the causes of a different name
        that the evidence does not exclude (0 when the two are indistinguishable on the
        held-out span).
    gain : float
        Held-out gain of the model with every cause found (``causes``), vs the baseline.
    baseline_nrmse, extended_nrmse : float
        Held-out NRMSE of the baseline and of that model.
    candidates : list of dict
        Every cause alone: ``cause``, ``model`` (class), ``equation``, ``gain``,
        ``heldout_nrmse``, ``coef``, ``excluded`` (why the evidence rules it out, "" if
        not: such a candidate is neither named nor the runner-up).
    causes : list of dict
        Step by step: ``cause``, ``model``, ``gain`` (over the model before it).
    evidence : dict
        Calibration-free evidence (see `afmlearn.freeosc.evidence`).
    track : HarmonicTrack
        Per-block harmonics (for figures).
    demod : Demodulation
        The fundamental's state (for figures).
    split_time_s : float
        Start of the held-out span [s].
    model : AbstractCause
        The baseline extended by every cause found, fitted before ``split_time_s``.
    assumptions : list of str
    """

    cause: str
    confidence: float
    gain: float
    baseline_nrmse: float
    extended_nrmse: float
    candidates: list[dict[str, Any]]
    causes: list[dict[str, Any]]
    evidence: dict[str, Any]
    track: HarmonicTrack
    demod: Demodulation
    split_time_s: float
    model: AbstractCause
    assumptions: list[str] = field(default_factory=list)

    def predict(self) -> NDArray[np.float64]:
        """``model``'s prediction of the whole record, shape (n,), record units."""
        return self.model.predict(self.demod)

    def to_dict(self) -> dict[str, Any]:
        """The report (JSON-ready with `afmlearn.io.jsonable`)."""
        best = next((c for c in self.causes), None)
        return {
            "cause": self.cause, "confidence": self.confidence, "gain": self.gain,
            "baseline": {"equation": LinearLever.equation, "heldout_nrmse": self.baseline_nrmse},
            "extended": {"equation": " + ".join(c["equation"] for c in self.causes)
                         if best else LinearLever.equation,
                         "heldout_nrmse": self.extended_nrmse},
            "candidates": self.candidates, "causes": self.causes, "evidence": self.evidence,
            "heldout": {"split_time_s": self.split_time_s,
                        "rule": "fit on the record before split_time_s, predict the rest"},
            "assumptions": self.assumptions,
            "harmonics_per_block": {
                "time_s": self.track.time_s, "amplitude": self.track.amplitude,
                "relative": self.track.relative, "phase_rad": np.angle(self.track.harmonics),
                "offset": self.track.offset},
        }


def default_causes(y: ArrayLike, demod: Demodulation, *, sample_rate_hz: float,
                   quality_factor: float = math.inf, detector_order: int = 4
                   ) -> list[AbstractCause]:
    """The causes tested by default; a higher mode only when a non-harmonic line is seen and
    quantisation only when the record is quantised. The detector map goes to ``x^4`` by
    default (a smooth map's next term; a cubic map cannot make a 4th harmonic)."""
    causes: list[AbstractCause] = [
        DetectorNonlinearity(order=detector_order), AcBiasDrive(),
        GapModulatedForce(quality_factor=quality_factor),
        DuffingStiffness(quality_factor=quality_factor)]
    peak = non_harmonic_peak(y, sample_rate_hz=sample_rate_hz, carrier_hz=demod.carrier_hz,
                             exclude_hz=2 * demod.cutoff_hz)
    if peak["relative"] > _MODE_LINE:
        causes.append(HigherMode(frequency_hz=peak["frequency_hz"]))
    step = quantisation_step(y)
    if math.isfinite(step):
        causes.append(Quantisation(step=step))
    return causes


def _split(demod: Demodulation, heldout_fraction: float) -> tuple[NDArray[np.intp],
                                                                   NDArray[np.intp], float]:
    idx = np.flatnonzero(demod.valid)
    cut = int(round(idx.size * (1.0 - heldout_fraction)))
    return idx[:cut], idx[cut:], float(demod.time_s[idx[cut]])


def _heldout(cause: AbstractCause, y: NDArray[np.float64], demod: Demodulation,
             train: NDArray[np.intp], test: NDArray[np.intp]) -> float:
    cause.fit(y[train], demod.take(train))
    return nrmse(cause.predict(demod.take(test)), y[test])


def diagnose_free(y: ArrayLike, *, sample_rate_hz: float, heldout_fraction: float = 0.3,
                  quality_factor: float = math.inf, block_periods: int = 200,
                  n_harmonics: int | None = None, causes: Sequence[AbstractCause] | None = None,
                  min_gain: float = MIN_GAIN) -> FreeOscillationDiagnosis:
    """Name the cause of the harmonics of a free oscillation and measure its held-out gain.

    Parameters
    ----------
    y : array-like, shape (n,)
        The record (deflection in any units), uniformly sampled, >= 20 periods.
    sample_rate_hz : float
        Sampling rate [Hz], > 0.
    heldout_fraction : float, default 0.3
        Fraction of the record at its end predicted, not fitted, in (0, 0.9).
    quality_factor : float, default inf
        The lever's Q (only the phase of its transfer function at the harmonics), > 0.
    block_periods : int, default 200
        Periods per block of the per-block harmonic evidence, >= 4.
    n_harmonics : int, optional
        Harmonics per block (default: up to 9, the Nyquist limit).
    causes : sequence of AbstractCause, optional
        The causes tested (default `default_causes`).
    min_gain : float, default MIN_GAIN
        Smallest held-out gain for a cause to be named, in [0, 1).

    Returns
    -------
    FreeOscillationDiagnosis

    Raises
    ------
    ValueError
        On settings out of range or a record too short or not finite.
    """
    y = np.asarray(y, dtype=float)
    if not 0.0 < heldout_fraction < 0.9:
        raise ValueError(f"heldout_fraction must lie in (0, 0.9), got {heldout_fraction!r}")
    if not 0.0 <= min_gain < 1.0:
        raise ValueError(f"min_gain must lie in [0, 1), got {min_gain!r}")
    demod = demodulate(y, sample_rate_hz=sample_rate_hz)
    spp = sample_rate_hz / demod.carrier_hz
    n_periods = y.size / spp
    if n_periods < 20:
        raise ValueError(f"y must hold at least 20 periods of its fundamental, got "
                         f"{n_periods:.1f}")
    nyquist = int(math.floor(spp / 2 * (1 - 1e-9)))
    n_h = min(9, nyquist) if n_harmonics is None else n_harmonics
    if not 3 <= n_h <= nyquist:
        raise ValueError(f"n_harmonics must lie in [3, {nyquist}] (Nyquist limit at {spp:.1f} "
                         f"samples per period), got {n_h!r}")
    if causes is None:
        causes = default_causes(y, demod, sample_rate_hz=sample_rate_hz,
                                quality_factor=quality_factor)
    train, test, split_time = _split(demod, heldout_fraction)
    base = _heldout(LinearLever(), y, demod, train, test)
    candidates = []
    for cause in causes:
        err = _heldout(cause, y, demod, train, test)
        candidates.append({"cause": cause.name, "model": type(cause).__name__,
                           "equation": cause.equation, "gain": 1.0 - err / base,
                           "heldout_nrmse": err, "coef": cause.coef_.tolist(),
                           "_obj": cause})
    track = track_harmonics(y, demod, n_harmonics=n_h, block_periods=block_periods)
    evidence = _evidence(y, demod, track, candidates, sample_rate_hz=sample_rate_hz)
    for c in candidates:
        c["excluded"] = _excluded(c, evidence)
    ranked = sorted((c for c in candidates if not c["excluded"]), key=lambda c: -c["gain"])
    steps: list[dict[str, Any]] = []
    current, current_err = None, base
    if ranked and ranked[0]["gain"] >= min_gain:
        first = ranked[0]
        steps.append({"cause": first["cause"], "model": first["model"],
                      "equation": first["equation"], "gain": first["gain"]})
        current, current_err = [first["_obj"]], first["heldout_nrmse"]
        for cand in ranked[1:]:
            if cand["cause"] in {s["cause"] for s in steps}:
                continue
            err = _heldout(Combined([*current, cand["_obj"]]), y, demod, train, test)
            step_gain = 1.0 - err / current_err
            if step_gain >= MIN_STEP_GAIN:
                steps.append({"cause": cand["cause"], "model": cand["model"],
                              "equation": cand["equation"], "gain": step_gain})
                current.append(cand["_obj"])
                current_err = err
    cause_name = steps[0]["cause"] if steps else "none"
    other = [c["gain"] for c in ranked if c["cause"] != cause_name]
    best_gain = ranked[0]["gain"] if ranked else 0.0
    if steps:
        runner = max(other, default=0.0)
        confidence = float(np.clip(1.0 - max(runner, 0.0) / best_gain, 0.0, 1.0))
    else:
        confidence = float(np.clip(1.0 - max(best_gain, 0.0) / min_gain, 0.0, 1.0))
    for c in candidates:
        c.pop("_obj")
    model = Combined(current) if current else LinearLever()
    model.fit(y[train], demod.take(train))
    logger.info("free oscillation: cause %s, held-out gain %.3f", cause_name,
                1.0 - current_err / base)
    return FreeOscillationDiagnosis(
        cause=cause_name, confidence=confidence, gain=1.0 - current_err / base,
        baseline_nrmse=base, extended_nrmse=current_err, candidates=candidates, causes=steps,
        evidence=evidence, track=track, demod=demod, split_time_s=split_time, model=model,
        assumptions=[
            "samples uniformly spaced at the stated rate; record units arbitrary (ratios, "
            "exponents, phases and gains do not depend on the detector sensitivity or k)",
            "the fundamental's amplitude and phase on the held-out span are its own "
            "demodulation (self-oscillation: no external clock); offsets and harmonics are "
            "predicted from coefficients fitted before split_time_s",
            f"lever transfer function at Omega = 1 with Q = {quality_factor:g} (phase of "
            "H(n Omega) only)",
        ])


def _excluded(candidate: dict[str, Any], evidence: dict[str, Any]) -> str:
    """Why a candidate is physically excluded whatever its gain ("" if it is not).

    A fixed-amplitude 2 omega drive is excluded when both the in-phase and the quadrature
    part of the 2nd harmonic scale with the amplitude (exponents resolved away from 0 at
    ``_EXPONENT_SIGMAS`` standard errors). A gap-modulated force is excluded when, for every
    power law tested, the force gradient it needs reaches snap-in (``F'/k >= 1``) or the
    frequency drift it implies exceeds ``_FREQUENCY_MARGIN`` times the measured drift of the
    block frequencies.
    """
    if candidate["model"] == "AcBiasDrive":
        return _not_a_fixed_drive(evidence)
    req = evidence.get("gap_force_requirement")
    if candidate["model"] != "GapModulatedForce" or not req:
        return ""
    measured = max(evidence["block_frequency_range"], 1e-9)
    needed = min(v["frequency_change_min"] for k, v in req.items() if k.startswith("m"))
    if needed > _FREQUENCY_MARGIN * measured:
        return (f"a gap-modulated force making this 2nd harmonic needs F'/k >= "
                f"{min(v['gradient_min'] for k, v in req.items() if k.startswith('m')):.2f} "
                f"and a frequency drift >= {needed:.2g} (relative) for the harmonics' drift; "
                f"measured {measured:.2g}")
    return ""


def _not_a_fixed_drive(evidence: dict[str, Any]) -> str:
    parts = (evidence["scaling"]["h2"], evidence["quadrature_scaling"]["h2"])
    if all(abs(p["exponent"]) > _EXPONENT_SIGMAS * p["exponent_stderr"] for p in parts):
        return ("a drive of fixed amplitude makes a 2nd harmonic independent of A; measured "
                f"exponents {parts[0]['exponent']:.2f} +- {parts[0]['exponent_stderr']:.2f} "
                f"(magnitude) and {parts[1]['exponent']:.2f} +- "
                f"{parts[1]['exponent_stderr']:.2f} (quadrature part)")
    return ""


def _evidence(y: NDArray[np.float64], demod: Demodulation, track: HarmonicTrack,
              candidates: list[dict[str, Any]], *, sample_rate_hz: float) -> dict[str, Any]:
    valid = demod.valid
    freq = demod.frequency_hz[valid]
    rel = track.relative.mean(axis=0)
    scaling = {f"h{n}": scaling_with_drift(track, n) for n in (2, 3)}
    duration = float(np.ptp(track.time_s)) if track.time_s.size else 0.0
    drift = scaling["h2"]["drift_per_s"] * duration
    block_freq = [float(np.mean(b)) for b in np.array_split(freq, max(track.time_s.size, 1))]
    gap = next((c for c in candidates if c["model"] == "GapModulatedForce"), None)
    extra: dict[str, Any] = {}
    if gap is not None and math.isfinite(drift):
        # only a drift resolved at 3 standard errors counts
        resolved = abs(scaling["h2"]["drift_per_s"]) > 3 * scaling["h2"]["drift_stderr"]
        extra["gap_force_requirement"] = gap_force_requirement(
            gap["coef"][0], float(track.amplitude.mean()),
            harmonic_drift=drift if resolved else 0.0)
    return {
        **extra,
        "harmonic_drift_over_record": {"h2": drift,
                                       "h3": scaling["h3"]["drift_per_s"] * duration},
        "block_frequency_range": float(np.ptp(block_freq)) / demod.carrier_hz,
        "carrier_hz": demod.carrier_hz,
        "samples_per_period": sample_rate_hz / demod.carrier_hz,
        "n_blocks": int(track.time_s.size),
        "relative_harmonics": rel.tolist(),
        "harmonic_noise_floor": float(np.mean(track.harmonic_sigma / track.amplitude)),
        "amplitude_range": [float(track.amplitude.min()), float(track.amplitude.max())],
        "scaling": scaling,
        "quadrature_scaling": {"h2": quadrature_scaling(track, 2)},
        "phase_lock": {f"h{n}": phase_lock(track, n) for n in (2, 3)},
        "dc_coupling": dc_coupling(track),
        "frequency_hz": {"median": float(np.median(freq)),
                         "p01": float(np.percentile(freq, 1)),
                         "p99": float(np.percentile(freq, 99)),
                         "min": float(freq.min()), "max": float(freq.max())},
        "non_harmonic_peak": non_harmonic_peak(y, sample_rate_hz=sample_rate_hz,
                                               carrier_hz=demod.carrier_hz,
                                               exclude_hz=2 * demod.cutoff_hz),
        "quantisation_step": quantisation_step(y),
    }
