"""Synthetic experiments matched to a recording, and the identifier scored on them.

Tuning for the user's own cantilever (``python scripts/tune.py
hparams_search=identifier_for_recording recording=PATH``): the identifier's settings are chosen
on simulated traces that look like the recording -- same lever, drive, sampling, amplitude and
noise -- but whose force is known. :func:`recording_calibration` reads what the recording says
(``afmlearn.io.read_trace``, never its labels) and measures what it does not (set-point
amplitude, noise level from the harmonic fit); :func:`matched_config` turns that into the
simulator's config (force law drawn from ``matched.ranges`` per experiment, as a dataset's
shards); :func:`evaluate` simulates the experiments once (cached shard files, reused by every
trial and worker), identifies each with ``cfg.identifier`` and scores the force against the
truth (``afmlearn.metrics.force_accuracy``). Each experiment is one fold: its running mean is
reported to the trial (:func:`afmlearn.tune.report`), so a poor setting is pruned early.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf, open_dict

from afmlearn.identify.identifier import ForceIdentifier
from afmlearn.identify.train import score, true_model
from afmlearn.io import read_trace, shard_path
from afmlearn.preprocess import calibrate, check_trace
from afmlearn.preprocess.harmonics import fit_harmonics
from afmlearn.simulate import simulate

from .context import report

__all__ = ["recording_calibration", "matched_config", "evaluate"]

log = logging.getLogger(__name__)

#: keys of the simulator config that ``matched_config`` sets from the recording
MATCHED_KEYS = ("cantilever.spring_constant_n_per_m", "cantilever.resonance_frequency_hz",
                "cantilever.quality_factor", "cantilever.gap_m", "scenario.omega",
                "scenario.samples_per_period", "scenario.n_periods",
                "excitation.free_amplitude_ratio", "noise.level")


def recording_calibration(path: str | Path, *, row: int | None = None) -> dict[str, float]:
    """What the simulator needs to imitate a recorded steady trace.

    Parameters
    ----------
    path : str or Path
        Trace file (trace format v1, or what ``afmlearn.io.read_trace`` reads); its labels are
        never read.
    row : int or None
        Row of a sweep or set-point series (None: a 1-D trace; row 0 of a 2-D one).

    Returns
    -------
    dict
        ``spring_constant_n_per_m``, ``resonance_frequency_hz``, ``quality_factor``,
        ``sample_rate_hz``, ``drive_frequency_hz``, ``gap_m`` (rest gap), ``omega``
        (f_drive / f0), ``samples_per_period``, ``n_periods`` (recorded drive periods),
        ``amplitude_m`` (set-point amplitude of the fundamental), ``free_amplitude_m``
        (from the file, else the set-point amplitude / 0.7), ``noise_level`` (white-noise std
        from the harmonic fit / free amplitude), ``excitation`` ("tip" or "base").

    Raises
    ------
    ValueError
        Not a readable steady trace (missing calibration, < 20 samples per period, ...).
    """
    trace = read_trace(path)
    if row is None and np.ndim(trace.deflection_m) == 2:
        row = 0
    check_trace(trace)
    cal = calibrate(trace, row=row)
    fit = fit_harmonics(cal.tau, cal.x, cal.omega)
    scale = float(np.mean(np.atleast_1d(trace.gap_m))) / float(np.mean(np.atleast_1d(cal.gap)))
    c = np.asarray(fit.coefficients, float)
    n = (c.size - 1) // 2
    amplitude = float(np.hypot(c[1], c[1 + n])) * scale if n >= 1 else math.nan
    if not math.isfinite(amplitude) or amplitude <= 0:
        amplitude = 0.5 * float(np.ptp(cal.x)) * scale
    free = trace.free_amplitude_m
    free_amplitude = float(free) if free else amplitude / 0.7
    f_drive = float(np.atleast_1d(trace.drive_frequency_hz)[row or 0])
    fs = float(trace.sample_rate_hz)
    n_samples = int(np.shape(cal.x)[-1])
    return {
        "spring_constant_n_per_m": float(trace.spring_constant_n_per_m),
        "resonance_frequency_hz": float(trace.resonance_frequency_hz),
        "quality_factor": float(trace.quality_factor),
        "sample_rate_hz": fs,
        "drive_frequency_hz": f_drive,
        "gap_m": float(np.atleast_1d(trace.gap_m)[row or 0]),
        "omega": f_drive / float(trace.resonance_frequency_hz),
        "samples_per_period": fs / f_drive,
        "n_periods": n_samples * f_drive / fs,
        "amplitude_m": amplitude,
        "free_amplitude_m": free_amplitude,
        "noise_level": float(fit.noise_rms) * scale / free_amplitude,
        "excitation": str(trace.excitation or "tip"),
    }


def matched_config(cfg: DictConfig, calibration: dict[str, Any]) -> DictConfig:
    """The simulator config of the matched experiments (a dataset of ``n_experiments`` shards).

    ``cfg`` is composed from ``conf/tune.yaml`` (simulator groups plus ``matched``); the lever,
    drive, sampling, amplitude and noise come from ``calibration``, the force law's parameters
    are drawn per experiment from ``matched.ranges``; ``output`` is a cache folder named by a
    hash of all of it.
    """
    m = cfg.matched
    n_exp = int(m.n_experiments)
    if n_exp < 1:
        raise ValueError(f"matched.n_experiments must be >= 1, got {n_exp}")
    spp = int(round(calibration["samples_per_period"]))
    if spp < 20:
        raise ValueError(f"recording: {spp} samples per drive period, the identifier needs >= 20")
    target = str(OmegaConf.select(cfg, "excitation._target_", default=""))
    if (calibration["excitation"] == "base") != target.endswith("BaseExcitation"):
        raise ValueError(f"excitation: the recording is {calibration['excitation']}-excited but "
                         f"the config simulates {target or 'nothing'} (pass "
                         f"excitation={calibration['excitation']})")
    # unresolved copy: ${cantilever.*} interpolations (scales, force) follow the new values
    sim = OmegaConf.create(OmegaConf.to_container(cfg, resolve=False))
    with open_dict(sim):
        for key in ("matched", "identifier", "hparams_search", "recording", "fold", "row",
                    "hydra"):
            sim.pop(key, None)
        sim.cantilever.spring_constant_n_per_m = calibration["spring_constant_n_per_m"]
        sim.cantilever.resonance_frequency_hz = calibration["resonance_frequency_hz"]
        sim.cantilever.quality_factor = calibration["quality_factor"]
        sim.cantilever.gap_m = calibration["gap_m"]
        sim.scenario.omega = calibration["omega"]
        sim.scenario.samples_per_period = spp
        sim.scenario.n_periods = int(min(max(calibration["n_periods"], 20), int(m.max_periods)))
        sim.excitation.free_amplitude_ratio = (calibration["free_amplitude_m"]
                                               / calibration["gap_m"])
        sim.noise.level = float(min(max(calibration["noise_level"], 0.0), 1.0))
        sim.seed = int(m.seed)
        sim.labels = True
        sim.progress = False
        sim.free_trace = True
        # a dataset folder needs count >= 2; experiment i depends on (seed, i) only
        sim.shard = {"index": 0, "count": max(n_exp, 2), "overwrite": False}
        sim.dataset = {"ranges": OmegaConf.to_container(m.ranges, resolve=True)}
        OmegaConf.resolve(sim)
        digest = hashlib.sha1(json.dumps(OmegaConf.to_container(sim), sort_keys=True,
                                         default=str).encode()).hexdigest()[:12]
        sim.output = str(Path(str(m.cache_dir)) / digest)
    return sim


def _experiment(sim: DictConfig, index: int) -> Path:
    """Path of matched experiment ``index`` (simulated now unless already on disk)."""
    one = sim.copy()
    with open_dict(one):
        one.shard.index = int(index)
    path = shard_path(Path(str(one.output)), int(index))
    if not path.exists():
        log.info("simulating matched experiment %d -> %s", index, path)
        simulate(one)
    return path


def _score(path: Path, identifier: ForceIdentifier) -> dict[str, Any]:
    """Identify one matched trace (labels unseen) and score it against its labels."""
    trace = read_trace(path)
    check_trace(trace)
    cal = calibrate(trace)
    identifier.fit(cal)
    labels = read_trace(path, labels=True).labels
    assert labels is not None
    truth = true_model(labels.model, omega=cal.omega, quality_factor=cal.quality_factor)
    return score(identifier, truth, force_n=np.asarray(labels.force_n, float),
                 gap_m=np.asarray(labels.extra["tip_sample_gap_m"], float),
                 model_json=labels.model, scales=cal.scales)


def evaluate(cfg: DictConfig) -> tuple[dict[str, float], dict[str, Any]]:
    """Mean force accuracy of ``cfg.identifier`` on the experiments matched to ``cfg.recording``.

    Parameters
    ----------
    cfg : DictConfig
        Composed from ``conf/tune.yaml``: ``recording`` (path), ``row``, ``fold`` (one
        experiment index, or null for all), ``matched`` (``n_experiments``, ``ranges``,
        ``max_periods``, ``seed``, ``cache_dir``, ``metric``), ``identifier`` and the simulator
        groups.

    Returns
    -------
    metrics : dict of str to float
        ``force_accuracy`` (mean over the experiments of ``matched.metric``, in [0, 1] or NaN),
        ``force_accuracy_<i>`` per experiment, ``runtime_s``.
    objects : dict
        ``calibration``, ``simulation`` (the matched simulator config), ``experiments``
        (paths), ``records`` (the full score of each experiment).

    Raises
    ------
    ValueError
        Bad settings or an unusable recording, naming the key.
    optuna.TrialPruned
        Inside a study, when the running mean is pruned after an experiment.
    """
    t0 = time.perf_counter()
    if not cfg.get("recording"):
        raise ValueError("recording must be the path of a recorded trace, got "
                         f"{cfg.get('recording')!r}")
    calibration = recording_calibration(str(cfg.recording), row=cfg.get("row"))
    sim = matched_config(cfg, calibration)
    n_exp = int(cfg.matched.n_experiments)
    fold = cfg.get("fold")
    if fold is not None and not 0 <= int(fold) < n_exp:
        raise ValueError(f"fold must be in [0, {n_exp - 1}] (matched.n_experiments), got {fold}")
    indices = range(n_exp) if fold is None else [int(fold)]
    metric = str(cfg.matched.get("metric", "whole"))
    if metric not in ("whole", "repulsive", "attractive", "near_a0"):
        raise ValueError(f"matched.metric must be whole, repulsive, attractive or near_a0, "
                         f"got {metric!r}")
    metrics: dict[str, float] = {}
    records, paths, values = [], [], []
    for step, i in enumerate(indices):
        path = _experiment(sim, i)
        identifier = instantiate(cfg.identifier, _convert_="all")
        if not isinstance(identifier, ForceIdentifier):
            raise ValueError(f"identifier must build a ForceIdentifier, got "
                             f"{type(identifier).__name__}")
        try:
            rec = _score(path, identifier)
            value = float(rec.get("force_accuracy", {}).get(metric, {}).get("accuracy", math.nan))
        except (ValueError, np.linalg.LinAlgError) as err:
            log.warning("experiment %d: identification failed: %s", i, err)
            rec, value = {"error": str(err)}, 0.0
        value = 0.0 if math.isnan(value) else value
        records.append(rec)
        paths.append(path)
        values.append(value)
        metrics[f"force_accuracy_{i}"] = value
        log.info("experiment %d: force accuracy (%s) %.4f", i, metric, value)
        report(float(np.mean(values)), step=step)
    metrics["force_accuracy"] = float(np.mean(values))
    metrics["runtime_s"] = time.perf_counter() - t0
    return metrics, {"calibration": calibration, "simulation": sim, "experiments": paths,
                     "records": records}
