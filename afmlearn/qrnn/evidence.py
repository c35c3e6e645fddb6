"""Calibrated mode-coupling probability per trace / per set-point, for other analyses.

`coupling_probability` is the one entry point other packages use (the ``higher_mode``
hypothesis of the diagnosis): it takes a recording (a `Trace`, an `Experiment` or a path) and
returns a `CouplingEvidence` with one calibrated probability per observation (a single trace:
one; a set-point series: one per set-point; a sweep: one per sweep point). The probability is
that of the checkpoint's calibration (:mod:`afmlearn.qrnn.calibration`, fitted on held-out
cantilevers); the flag uses the checkpoint's threshold for its stated false-flag rate.

Nothing here reads ``/labels``. The model is loaded once per checkpoint path and reused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, final

import numpy as np
from numpy.typing import NDArray

from afmlearn.io import Experiment, Trace, read_trace
from afmlearn.qrnn.infer import DEFAULT_CHECKPOINT, calibration_of, load_module, predict_trace

__all__ = ["CouplingEvidence", "coupling_probability"]


@final
@dataclass(frozen=True)
class CouplingEvidence:
    """Calibrated coupling probabilities of the observations of one recording.

    Attributes
    ----------
    probability : ndarray, shape (n_obs,)
        ``P(modes >= 2 carry > 5.5 % of the RMS tip motion)`` per observation (set-point,
        sweep point or the trace), calibrated; the raw mean window score when
        ``calibrated`` is False.
    flag : ndarray of bool, shape (n_obs,)
        ``probability >= threshold`` and driven inside the checkpoint's training band
        (:func:`afmlearn.qrnn.infer.training_band`).
    raw_score : ndarray, shape (n_obs,)
        Mean window score of the network (uncalibrated; ranks but is not a probability).
    forecast_nrmse : ndarray, shape (n_obs,)
        NRMSE of the network's forecast of the measured next period (a recording the network
        cannot forecast, e.g. > 0.1, is out of its distribution: distrust the probability).
    gap_m : ndarray, shape (n_obs,)
        Rest gap of each observation [m].
    drive_frequency_hz : ndarray, shape (n_obs,)
        Drive frequency of each observation [Hz].
    threshold : float
        Flag threshold (the checkpoint's calibrated one, or 0.5 uncalibrated).
    false_flag_rate : float or None
        The false-flag rate the threshold was chosen for on the calibration set.
    calibrated : bool
        Whether the checkpoint carries a calibration.
    checkpoint : str
        The checkpoint used.
    base_rate : ndarray, shape (n_obs,)
        Share of coupled traces in the calibration set of each observation's kind (steady
        records / sweep points): the prior the calibrated probability carries (NaN when
        uncalibrated). ``logit(probability) - logit(base_rate)`` is the log likelihood ratio
        of the network's evidence (:meth:`log_likelihood_ratio`).
    """

    probability: NDArray[np.float64]
    flag: NDArray[np.bool_]
    raw_score: NDArray[np.float64]
    forecast_nrmse: NDArray[np.float64]
    gap_m: NDArray[np.float64]
    drive_frequency_hz: NDArray[np.float64]
    threshold: float
    false_flag_rate: float | None
    calibrated: bool
    checkpoint: str
    base_rate: NDArray[np.float64]

    def log_likelihood_ratio(self, *, eps: float = 1e-4) -> NDArray[np.float64]:
        """``logit(p) - logit(base_rate)`` per observation (NaN when uncalibrated).

        Bayes: the calibrated probability is the posterior under the calibration set's base
        rate, so this difference is what the records add to any prior. ``p`` and the base rate
        are clipped to ``[eps, 1 - eps]``.
        """
        def logit(v: NDArray[np.float64]) -> NDArray[np.float64]:
            v = np.clip(v, eps, 1.0 - eps)
            return np.log(v / (1.0 - v))
        return logit(self.probability) - logit(self.base_rate)

    @property
    def max_probability(self) -> float:
        """Largest probability over the observations (the experiment's strongest evidence)."""
        return float(np.max(self.probability))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types."""
        return {"probability": self.probability.tolist(), "flag": self.flag.tolist(),
                "raw_score": self.raw_score.tolist(),
                "forecast_nrmse": self.forecast_nrmse.tolist(), "gap_m": self.gap_m.tolist(),
                "drive_frequency_hz": self.drive_frequency_hz.tolist(),
                "threshold": self.threshold, "false_flag_rate": self.false_flag_rate,
                "calibrated": self.calibrated, "checkpoint": self.checkpoint,
                "base_rate": self.base_rate.tolist(), "max_probability": self.max_probability}


@lru_cache(maxsize=4)
def _cached_module(path: str) -> tuple[Any, dict[str, Any]]:
    module, run, _ = load_module(path)
    return module, run


def coupling_probability(recording: Trace | Experiment | str | os.PathLike[str], *,
                         checkpoint: str | os.PathLike[str] | None = None
                         ) -> CouplingEvidence:
    """Calibrated probability that a second (or third) mode takes part, per observation.

    Parameters
    ----------
    recording : Trace, Experiment or path
        A steady trace, a set-point series, a sweep (one observation per row), an `Experiment`
        of steady records, or a trace file (read without labels).
    checkpoint : path, optional
        Default: the shipped checkpoint.

    Returns
    -------
    CouplingEvidence

    Raises
    ------
    ValueError
        Input the identify/diagnose checks refuse (clipped, NaN, < 20 samples per period,
        non-positive gap), a record shorter than one input period plus the forecast horizon,
        an approach ramp or lock-in curves (the network reads steady deflection records only).
    """
    path = str(Path(checkpoint if checkpoint is not None else DEFAULT_CHECKPOINT).resolve())
    module, run = _cached_module(path)
    if isinstance(recording, str | os.PathLike):
        # one trace with its rows (a sweep keeps its kind and calibration; an Experiment
        # would split it into single steady records)
        recording = read_trace(recording)
    if isinstance(recording, Experiment):
        observations = list(recording)
    elif isinstance(recording, Trace):
        observations = [recording]
    else:
        raise ValueError(f"recording must be a Trace, an Experiment or a path, got "
                         f"{type(recording).__name__}")
    rows: list[dict[str, Any]] = []
    threshold, summary = 0.5, None
    for obs in observations:
        if obs.deflection_m is None or obs.is_ramp:
            raise ValueError("recording: the QRNN reads steady deflection records (single "
                             "traces, set-point series, sweeps), not approach ramps or lock-in "
                             "curves")
        summary = predict_trace(obs, module, run)["summary"]
        threshold = summary["threshold"]
        cal = calibration_of(run, "sweep" if obs.is_sweep else "steady")
        src = cal.source if cal is not None else {}
        rate = (float(src["n_coupled"]) / float(src["n_traces"])
                if src.get("n_traces") else float("nan"))
        gaps = np.broadcast_to(np.asarray(obs.gap_m, dtype=float), (obs.n_points,)
                               ) if obs.has_rows else np.array([float(obs.gap_m)])
        for t in summary["traces"]:
            rows.append({**t, "gap_m": float(gaps[t["row"]]), "base_rate": rate})
    assert summary is not None  # an Experiment holds at least one observation
    prob = np.array([r["score"] for r in rows])
    return CouplingEvidence(
        probability=prob, flag=np.array([bool(r["flag"]) for r in rows]),
        raw_score=np.array([r["raw_score"] for r in rows]),
        forecast_nrmse=np.array([r["forecast_nrmse_per_period"][0] for r in rows]),
        gap_m=np.array([r["gap_m"] for r in rows]),
        drive_frequency_hz=np.array([r["drive_frequency_hz"] for r in rows]),
        threshold=float(threshold), false_flag_rate=summary["false_flag_rate"],
        calibrated=bool(summary["calibrated"]), checkpoint=path,
        base_rate=np.array([r["base_rate"] for r in rows]))
