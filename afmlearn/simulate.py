"""Simulate a labelled trace, sweep or dataset shard from a composed Hydra config.

:func:`simulate` is the one function behind ``scripts/simulate.py`` (and the tests): it
instantiates the objects of ``conf/`` (``_target_`` nodes), runs the scenario with a progress
bar, passes the deflection through the sensor chain and writes trace format v1
(``design.md`` section 2) atomically. Sweeps are streamed to disk row by row as the simulator
yields them. ``simulator/`` stays free of Hydra and HDF5; all of that lives here.

Config contract (see ``conf/simulate.yaml``)
--------------------------------------------
``cantilever``
    SI calibration keys (``spring_constant_n_per_m``, ``resonance_frequency_hz``,
    ``quality_factor``, ``n_modes``, ``gap_m`` = ``L_ref``, ``tip_radius_m``, optional
    ``frequency_ratios``, ``higher_quality_factors``, ``contact_quality_factors``, ``name``) and
    a ``modes`` node with a ``_target_`` that builds the dimensionless
    :class:`simulator.Cantilever` (``Cantilever.rectangular`` or an explicit ``Cantilever``).
``force``, ``scenario``, ``sensor``, ``scales``
    ``_target_`` nodes, instantiated recursively. A ``spectroscopy`` scenario may give its
    rest gaps in metres (``scenario.gaps_m``), converted here with ``cantilever.gap_m``.
``excitation``
    ``_target_`` (an excitation class) plus ``free_amplitude_ratio`` (free tip amplitude /
    rest gap) or an explicit dimensionless ``amplitude``.
root keys
    ``seed``, ``output``, ``noise.level``, ``progress``, ``free_trace``,
    ``free_trace_periods``, ``labels``, ``description``, ``shard.{index,count}``,
    ``dataset.ranges``.
"""

from __future__ import annotations

import collections
import copy
import logging
import math
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from hydra.errors import InstantiationException
from hydra.utils import get_class, instantiate, to_absolute_path
from omegaconf import DictConfig, ListConfig, OmegaConf, open_dict
from tqdm.auto import tqdm

from afmlearn.curves.writer import curve_trace
from afmlearn.io import Labels, Trace, TraceWriter, shard_path, write_manifest, write_trace
from simulator import (
    AbstractExcitation,
    Cantilever,
    Scales,
    SensorChain,
    SimulationResult,
    SteadyState,
    Sweep,
    System,
)
from simulator.forces import (
    AbstractForceModel,
    Electrostatic,
    ForceSum,
    LennardJones,
    NoInteraction,
    SphereVdW,
)
from simulator.labels import labels_to_si as si_labels
from simulator.labels import recorded_drive_phase
from simulator.scenarios import AbstractScenario, LockInCurve, Spectroscopy

__all__ = ["simulate", "build", "si_labels", "REGIME_CODES", "EV"]

log = logging.getLogger(__name__)

#: one electronvolt [J]
EV = 1.602176634e-19
#: numeric codes of the ``regime`` label, used for the per-row scalar ``regime_code`` of sweeps
REGIME_CODES: dict[str, int] = {"free": 0, "attractive": 1, "repulsive": 2,
                                "permanent_contact": 3}
#: dimensionless label -> (SI name, unit attribute of Scales or None)
#: config groups searched for a bare key of ``dataset.ranges``
_GROUPS = ("excitation", "scenario", "force", "cantilever", "sensor")


# ---------------------------------------------------------------------------- public API
def simulate(cfg: DictConfig) -> tuple[dict[str, Any], dict[str, Any]]:
    """Simulate what ``cfg`` describes and write it as a trace file (format v1).

    Parameters
    ----------
    cfg : omegaconf.DictConfig
        A config composed from ``conf/simulate.yaml`` (left unchanged).

    Returns
    -------
    metrics : dict
        ``amplitude_m`` [m] (first-harmonic amplitude; max over rows for a sweep or a
        set-point series),
        ``free_amplitude_m`` [m], ``set_point`` [-] (amplitude / free amplitude),
        ``contact_fraction`` [-] (mean over rows for a sweep), ``dissipated_energy_j`` and
        ``dissipated_energy_ev`` (energy into the sample per drive cycle; mean over rows),
        ``peak_force_n`` [N] (largest repulsive force), ``coupling_strength`` [-] (max over
        rows), ``regime`` (most common), ``n_points``, ``n_samples``, ``scenario``,
        ``model``, ``seed``, ``runtime_s`` [s], ``output`` (path of the file written) and, for
        shards, ``manifest``. A shard whose file already exists (an earlier, interrupted run
        of the same dataset) is skipped unless ``shard.overwrite`` is true; its metrics are
        then only ``output``, ``skipped=True``, ``manifest``, ``seed``, ``runtime_s``.
    objects : dict
        ``cfg`` (the effective config: shard seed and drawn parameters applied),
        ``scales``, ``cantilever``, ``force``, ``excitation``, ``scenario``, ``sensor``,
        ``system``, ``result`` (:class:`simulator.SimulationResult`, None for sweeps, which
        are streamed), ``free_result`` (or None), ``path``, ``manifest`` (or None),
        ``drawn`` (parameters drawn from ``dataset.ranges``).

    Raises
    ------
    ValueError
        For bad settings, naming the config key and the allowed range.
    """
    t0 = time.perf_counter()
    cfg = _checked_root(cfg)
    cfg, drawn = _apply_shard(cfg)
    path, folder = _output_path(cfg)
    if folder is not None and path.exists() and not cfg.shard.overwrite:
        # resume an interrupted dataset: shard files are written atomically, so an existing
        # one is complete
        manifest = _update_manifest(folder)
        log.info("shard %s exists, skipped (shard.overwrite=true to redo it)", path)
        metrics = {"output": str(path), "skipped": True, "manifest": str(manifest),
                   "seed": int(cfg.seed), "runtime_s": time.perf_counter() - t0}
        return metrics, {"cfg": cfg, "path": path, "manifest": manifest, "drawn": drawn}
    obj = build(cfg)
    system, scenario, scales = obj["system"], obj["scenario"], obj["scales"]

    free_sc = _free_scenario(obj, cfg.free_trace_periods) if cfg.free_trace else None
    total = scenario.total_samples(system) + (
        free_sc.total_samples(_free_system(system)) if free_sc is not None else 0)
    desc = f"{scenario.name}: {obj['force'].name}"
    with _progress_bar(total, enabled=bool(cfg.progress), desc=desc) as bar:
        if isinstance(scenario, Sweep):
            result = None
            free = _run_free(obj, free_sc, bar)
            summary = _write_sweep(cfg, obj, path, free, bar)
        elif isinstance(scenario, Spectroscopy):
            result = scenario.run(system, progress=bar)
            free = _run_free(obj, free_sc, bar)
            summary = _write_series(cfg, obj, path, result, free)
        elif isinstance(scenario, LockInCurve):
            result = scenario.run(system, progress=bar)
            free = None  # the curve starts far from the sample: its first points are free
            summary = _write_curve(cfg, obj, path, result)
        else:
            result = scenario.run(system, progress=bar)
            free = _run_free(obj, free_sc, bar)
            summary = _write_single(cfg, obj, path, result, free)
    manifest = _update_manifest(folder) if folder is not None else None

    x_ref_m = obj["free_amplitude"] * scales.length
    metrics: dict[str, Any] = {
        "model": obj["force"].name,
        "scenario": scenario.name,
        "seed": int(cfg.seed),
        "n_points": summary["n_points"],
        "n_samples": summary["n_samples"],
        "amplitude_m": summary["amplitude_m"],
        "free_amplitude_m": x_ref_m,
        "set_point": summary["amplitude_m"] / x_ref_m,
        "contact_fraction": summary["contact_fraction"],
        "dissipated_energy_j": summary["dissipated_energy_j"],
        "dissipated_energy_ev": summary["dissipated_energy_j"] / EV,
        "peak_force_n": summary["peak_force_n"],
        "coupling_strength": summary["coupling_strength"],
        "regime": summary["regime"],
        "runtime_s": time.perf_counter() - t0,
        "output": str(path),
    }
    if manifest is not None:
        metrics["manifest"] = str(manifest)
    log.info("wrote %s (%s, %s, %.2f s)", path, scenario.name, obj["force"].name,
             metrics["runtime_s"])
    objects = {**obj, "cfg": cfg, "result": result, "free_result": free, "path": path,
               "manifest": manifest, "drawn": drawn}
    return metrics, objects


def build(cfg: DictConfig) -> dict[str, Any]:
    """Instantiate the simulation objects of a composed config (nothing is run).

    Parameters
    ----------
    cfg : omegaconf.DictConfig
        A config composed from ``conf/simulate.yaml``.

    Returns
    -------
    dict
        ``scales`` (:class:`simulator.Scales`), ``cantilever``, ``force``, ``scenario``,
        ``excitation``, ``system``, ``sensor``, ``omega_ref`` (dimensionless frequency at
        which the free amplitude is defined) and ``free_amplitude`` (free tip amplitude at
        ``omega_ref``, units of the rest gap; the sensor's reference amplitude ``x_ref``).

    Raises
    ------
    ValueError
        Naming the config key, when a setting is out of range or unknown.
    """
    scales = _instantiate(cfg.scales, "scales", Scales)
    cantilever = _instantiate(cfg.cantilever.modes, "cantilever.modes", Cantilever)
    n_modes = cfg.cantilever.get("n_modes")
    if n_modes is not None and int(n_modes) != cantilever.n_modes:
        raise ValueError(f"cantilever.n_modes must match the modes it builds "
                         f"({cantilever.n_modes}), got {n_modes}")
    force = _instantiate(cfg.force, "force", AbstractForceModel)
    scenario = _instantiate(_scenario_node(cfg), "scenario", AbstractScenario)
    omega_ref = _reference_omega(scenario)
    excitation = _excitation(cfg.excitation, cantilever, omega_ref)
    free_amplitude = excitation.free_amplitude(cantilever, omega_ref)
    if not (math.isfinite(free_amplitude) and free_amplitude > 0.0):
        raise ValueError("excitation.amplitude must give a free amplitude > 0, got "
                         f"{free_amplitude!r}")
    _check_wall(force, excitation, free_amplitude, scenario)
    system = System(cantilever, force, excitation)
    sensor = _instantiate(cfg.sensor, "sensor", SensorChain)
    return {"scales": scales, "cantilever": cantilever, "force": force, "scenario": scenario,
            "excitation": excitation, "system": system, "sensor": sensor,
            "omega_ref": omega_ref, "free_amplitude": free_amplitude}


# ---------------------------------------------------------------------------- config checks
def _range_error(key: str, allowed: str, value: Any) -> ValueError:
    return ValueError(f"{key} must be {allowed}, got {value!r}")


def _checked_root(cfg: DictConfig) -> DictConfig:
    """A private copy of ``cfg`` with the root keys validated."""
    if not isinstance(cfg, DictConfig):
        raise ValueError(f"cfg must be an omegaconf DictConfig, got {type(cfg).__name__}")
    cfg = copy.deepcopy(cfg)
    missing = [k for k in ("cantilever", "force", "scenario", "excitation", "sensor", "scales",
                           "seed", "output") if k not in cfg]
    if missing:
        raise ValueError(f"cfg: missing config keys {missing} (compose conf/simulate.yaml)")
    level = OmegaConf.select(cfg, "noise.level", default=0.0)
    if not _is_real(level) or not 0.0 <= float(level) <= 1.0:
        raise _range_error("noise.level", "a number in [0, 1]", level)
    seed = cfg.seed
    if not _is_int(seed) or seed < 0:
        raise _range_error("seed", "an integer >= 0", seed)
    count = OmegaConf.select(cfg, "shard.count", default=1)
    index = OmegaConf.select(cfg, "shard.index", default=0)
    if not _is_int(count) or count < 1:
        raise _range_error("shard.count", "an integer >= 1", count)
    if not _is_int(index) or not 0 <= index < count:
        raise _range_error("shard.index", f"an integer in [0, {count})", index)
    if not isinstance(cfg.output, str) or not cfg.output.strip():
        raise _range_error("output", "a non-empty path", cfg.output)
    periods = cfg.get("free_trace_periods", 20)
    if not _is_real(periods) or not float(periods) > 0:
        raise _range_error("free_trace_periods", "a number > 0", periods)
    with _open_struct(cfg):
        cfg.shard = {"index": int(index), "count": int(count),
                     "overwrite": bool(OmegaConf.select(cfg, "shard.overwrite", default=False))}
        cfg.free_trace_periods = float(periods)
        for key, default in (("progress", True), ("free_trace", True), ("labels", True),
                             ("description", None)):
            cfg[key] = cfg.get(key, default)
    return cfg


def _is_int(x: Any) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool)


def _is_real(x: Any) -> bool:
    return (isinstance(x, int | float | np.integer | np.floating) and not isinstance(x, bool)
            and math.isfinite(float(x)))


@contextmanager
def _open_struct(cfg: DictConfig) -> Iterator[None]:
    flag = OmegaConf.is_struct(cfg)
    OmegaConf.set_struct(cfg, False)
    try:
        yield
    finally:
        OmegaConf.set_struct(cfg, flag)


def _apply_shard(cfg: DictConfig) -> tuple[DictConfig, dict[str, float]]:
    """Shard ``i``: seed ``seed + i`` and ``dataset.ranges`` drawn from ``rng([seed, i])``."""
    index = int(cfg.shard.index)
    base_seed = int(cfg.seed)
    ranges = OmegaConf.select(cfg, "dataset.ranges", default=None)
    leaves = _range_leaves(ranges, "") if ranges is not None else {}
    drawn: dict[str, float] = {}
    rng = np.random.default_rng([base_seed, index])
    with _open_struct(cfg):
        cfg.seed = base_seed + index
        for key in sorted(leaves):
            bounds = leaves[key]
            if (len(bounds) != 2 or not all(_is_real(b) for b in bounds)
                    or bounds[0] > bounds[1]):
                raise _range_error(f"dataset.ranges.{key}",
                                   "a pair [low, high] of numbers with low <= high",
                                   list(bounds))
            target = _resolve_key(cfg, key)
            value = float(rng.uniform(float(bounds[0]), float(bounds[1])))
            OmegaConf.update(cfg, target, value, merge=False)
            drawn[target] = value
    return cfg, drawn


def _range_leaves(node: Any, prefix: str) -> dict[str, list[Any]]:
    """``dataset.ranges`` as ``{dotted key: [low, high]}`` (nested mappings are flattened)."""
    if isinstance(node, ListConfig | list | tuple):
        return {prefix: list(node)}
    if not isinstance(node, DictConfig | Mapping):
        raise _range_error(f"dataset.ranges{'.' + prefix if prefix else ''}",
                           "a mapping {key: [low, high]}", node)
    out: dict[str, list[Any]] = {}
    for key, value in node.items():
        out.update(_range_leaves(value, f"{prefix}.{key}" if prefix else str(key)))
    return out


def _resolve_key(cfg: DictConfig, key: str) -> str:
    """Full config path of a ``dataset.ranges`` key (dotted path, or unique bare name)."""
    sentinel = object()
    if "." in key:
        if OmegaConf.select(cfg, key, default=sentinel) is sentinel:
            raise ValueError(f"dataset.ranges: no config key {key!r}")
        return key
    hits = [f"{g}.{key}" for g in _GROUPS if isinstance(cfg.get(g), DictConfig) and key in cfg[g]]
    if len(hits) != 1:
        where = "none of" if not hits else f"several ({hits}) of"
        raise ValueError(f"dataset.ranges: key {key!r} is in {where} the groups {_GROUPS}; "
                         "give a dotted path such as excitation.free_amplitude_ratio")
    return hits[0]


def _output_path(cfg: DictConfig) -> tuple[Path, Path | None]:
    """(trace file to write, dataset folder or None)."""
    out = Path(to_absolute_path(cfg.output))
    if cfg.shard.count > 1:
        if out.suffix == ".h5":
            raise ValueError(f"output must be a folder (not a .h5 file) when shard.count > 1, "
                             f"got {cfg.output!r}")
        out.mkdir(parents=True, exist_ok=True)
        return shard_path(out, int(cfg.shard.index)), out
    if out.suffix != ".h5":
        raise ValueError(f"output must be a .h5 file when shard.count == 1, got {cfg.output!r}")
    out.parent.mkdir(parents=True, exist_ok=True)
    return out, None


def _instantiate(node: Any, key: str, kind: type) -> Any:
    """``hydra.utils.instantiate(node)``; errors become ``ValueError`` naming ``key``."""
    if not isinstance(node, DictConfig) or "_target_" not in node:
        raise ValueError(f"{key} must be a config node with a _target_, got {node!r}")
    try:
        obj = instantiate(node, _convert_="all")
    except InstantiationException as err:
        cause = err.__cause__ if err.__cause__ is not None else err
        raise ValueError(f"{key}: {cause}") from err
    if not isinstance(obj, kind):
        raise ValueError(f"{key}: _target_ {node._target_!r} must build a {kind.__name__}, "
                         f"got {type(obj).__name__}")
    return obj


def _scenario_node(cfg: DictConfig) -> DictConfig:
    """``cfg.scenario`` with ``gaps_m`` [m] (spectroscopy) converted to ``gaps`` [L_ref]."""
    node = cfg.scenario
    if not isinstance(node, DictConfig) or "gaps_m" not in node:
        return node
    gaps_m = node.get("gaps_m")
    if isinstance(gaps_m, ListConfig):
        gaps_m = OmegaConf.to_container(gaps_m, resolve=True)
    node = copy.deepcopy(node)
    with open_dict(node):
        del node["gaps_m"]
        if gaps_m is None:
            return node
        values = gaps_m if isinstance(gaps_m, list) else [gaps_m]
        if not values or not all(_is_real(v) and v > 0 for v in values):
            raise _range_error("scenario.gaps_m", "a non-empty list of rest gaps > 0 [m]",
                               gaps_m)
        if node.get("gaps") is not None:
            raise ValueError("scenario.gaps_m and scenario.gaps are both given: give the rest "
                             "gaps once (gaps_m in metres, or gaps in units of "
                             "cantilever.gap_m)")
        node["gaps"] = [float(v) / float(cfg.cantilever.gap_m) for v in values]
    return node


def _reference_omega(scenario: AbstractScenario) -> float:
    """Drive frequency at which the free amplitude is defined (f0 for a sweep across it)."""
    if isinstance(scenario, Sweep):
        lo, hi = scenario.omega_start, scenario.omega_stop
        return 1.0 if lo <= 1.0 <= hi else lo
    return float(scenario.omega)


def _excitation(node: DictConfig, cantilever: Cantilever, omega: float) -> AbstractExcitation:
    spec = OmegaConf.to_container(node, resolve=True)
    assert isinstance(spec, dict)
    target = spec.pop("_target_", None)
    ratio = spec.pop("free_amplitude_ratio", None)
    amplitude = spec.pop("amplitude", None)
    if spec:
        raise ValueError(f"excitation: unknown keys {sorted(spec)} (allowed: _target_, "
                         "free_amplitude_ratio, amplitude)")
    try:
        cls = get_class(str(target))
    except Exception as err:  # hydra raises ImportError or ValueError subclasses
        raise ValueError(f"excitation._target_: cannot import {target!r} ({err})") from err
    if not (isinstance(cls, type) and issubclass(cls, AbstractExcitation)):
        raise ValueError(f"excitation._target_ must name an excitation class, got {target!r}")
    if amplitude is not None:
        if not _is_real(amplitude) or not amplitude > 0:
            raise _range_error("excitation.amplitude", "a number > 0 (or null)", amplitude)
        return cls(amplitude=float(amplitude))
    if not _is_real(ratio) or not ratio > 0:
        raise _range_error("excitation.free_amplitude_ratio",
                           "a number > 0 (or set excitation.amplitude)", ratio)
    return cls.for_free_amplitude(cantilever, omega, float(ratio))


def _has_wall(force: AbstractForceModel) -> bool:
    terms = force.terms if isinstance(force, ForceSum) else (force,)
    if all(isinstance(t, NoInteraction) for t in terms):
        return True  # nothing to crash into
    return force.has_contact or any(isinstance(t, LennardJones) and t.repulsion > 0
                                    for t in terms)


def _check_wall(force: AbstractForceModel, excitation: AbstractExcitation,
                free_amplitude: float, scenario: AbstractScenario) -> None:
    """Attractive-only forces diverge at ``z = 0``: refuse free orbits that reach the sample."""
    if _has_wall(force):
        return
    gaps = [float(getattr(scenario, g)) for g in ("gap", "gap_end") if hasattr(scenario, g)]
    if isinstance(scenario, Spectroscopy):
        gaps.extend(scenario.rest_gaps(free_amplitude).tolist())
    gap = min(gaps)
    reach = free_amplitude + excitation.gap_modulation
    if reach >= gap:
        raise ValueError(
            f"excitation.free_amplitude_ratio: force {force.name!r} has no repulsive wall, so "
            f"the free orbit (amplitude {reach:.3g} rest gaps) must stay below the smallest "
            f"rest gap {gap:.3g}; use e.g. excitation.free_amplitude_ratio=0.5")


def _singular_terms(force: AbstractForceModel) -> list[str]:
    """Names of the terms evaluated at the raw gap that diverge at ``z = 0``."""
    terms = force.terms if isinstance(force, ForceSum) else (force,)
    return [t.name for t in terms if isinstance(t, LennardJones | Electrostatic | SphereVdW)]


def _check_trajectory(force: AbstractForceModel, gap: np.ndarray) -> None:
    """Refuse trajectories that crossed ``z = 0`` through a singular term (not physical)."""
    singular = _singular_terms(force)
    z_min = float(np.min(gap))
    if singular and z_min <= 0.0:
        raise ValueError(
            f"force: the tip reached z = {z_min:.3g} L_ref <= 0, where the {singular} term(s) "
            f"of {force.name!r} diverge, so the trajectory is not physical. For lj refine the "
            "step (scenario.integrator.substeps=10) or lower the amplitude; with a contact "
            "law keep the indentation below a0 (a stiffer sample, a smaller amplitude or "
            "step).")


# ---------------------------------------------------------------------------- running
@contextmanager
def _progress_bar(total: int, *, enabled: bool, desc: str) -> Iterator[Any]:
    """A tqdm bar whose ``update`` is the simulator's ``progress(n)`` callback."""
    bar = tqdm(total=max(int(total), 1), disable=None if enabled else True, desc=desc,
               unit="sample", unit_scale=True, dynamic_ncols=True, leave=False)
    try:
        yield bar.update
    finally:
        bar.close()


def _free_system(system: System) -> System:
    return System(system.cantilever, NoInteraction(), system.excitation)


def _free_scenario(obj: dict[str, Any], periods: float) -> SteadyState:
    """Short steady no-interaction run: same drive, same sampling rate as the scenario.

    It starts on the exact linear free orbit, so nothing needs to settle.
    """
    scenario = obj["scenario"]
    omega = obj["omega_ref"]
    spp = 2.0 * math.pi / (omega * scenario.dt)
    return SteadyState(omega=omega, gap=1.0, n_periods=periods, settle_periods=0.0,
                       samples_per_period=spp, integrator=scenario.integrator)


def _run_free(obj: dict[str, Any], sc: SteadyState | None, bar: Any) -> SimulationResult | None:
    if sc is None:
        return None
    return sc.run(_free_system(obj["system"]), progress=bar)


# ---------------------------------------------------------------------------- writing
def _calibration(cfg: DictConfig, obj: dict[str, Any]) -> dict[str, Any]:
    """Root attributes of the trace file (everything but the arrays)."""
    c = cfg.cantilever
    scales: Scales = obj["scales"]
    cl: Cantilever = obj["cantilever"]
    exc: AbstractExcitation = obj["excitation"]
    ell = scales.length
    meta: dict[str, Any] = {
        "spring_constant_n_per_m": float(c.spring_constant_n_per_m),
        "quality_factor": float(c.quality_factor),
        "resonance_frequency_hz": float(c.resonance_frequency_hz),
        "free_amplitude_m": obj["free_amplitude"] * ell,
        "excitation": exc.kind,
        "tip_radius_m": float(c.tip_radius_m) if c.get("tip_radius_m") is not None else None,
        "description": cfg.description or _description(cfg, obj),
    }
    if exc.kind == "base":
        meta["dither_amplitude_m"] = exc.amplitude * ell
    if cl.n_modes > 1:
        meta["higher_mode_frequencies_hz"] = (scales.resonance_frequency
                                              * np.asarray(cl.frequency_ratios[1:]))
    return meta


def _description(cfg: DictConfig, obj: dict[str, Any]) -> str:
    name = cfg.cantilever.get("name") or "cantilever"
    return (f"afmlearn simulation: {obj['scenario'].name} scenario, force "
            f"{obj['force'].name}, {name} ({obj['cantilever'].n_modes} mode(s)), "
            f"{obj['excitation'].kind} excitation, seed {int(cfg.seed)}")


def _model_json(cfg: DictConfig, obj: dict[str, Any]) -> dict[str, Any]:
    """The ``/labels`` model record: everything needed to reproduce the trace."""
    scales: Scales = obj["scales"]
    force_cfg = OmegaConf.to_container(cfg.force, resolve=True)
    exc: AbstractExcitation = obj["excitation"]
    return {
        "name": obj["force"].name,
        "force": obj["force"].to_dict(),
        "force_config": _without_key(force_cfg, "scales"),
        "cantilever": {**obj["cantilever"].to_dict(),
                       "config": _without_key(OmegaConf.to_container(cfg.cantilever,
                                                                     resolve=True), "modes")},
        "excitation": {"kind": exc.kind, "amplitude": exc.amplitude,
                       "omega_ref": obj["omega_ref"], "free_amplitude": obj["free_amplitude"]},
        "scenario": _jsonable(obj["scenario"].to_dict()),
        "sensor": _jsonable(obj["sensor"].to_dict()),
        "seed": int(cfg.seed),
        "shard": {"index": int(cfg.shard.index), "count": int(cfg.shard.count)},
        "calibration": {
            "spring_constant_n_per_m": scales.spring_constant,
            "resonance_frequency_hz": scales.resonance_frequency,
            "length_m": scales.length,
            "force_unit_n": scales.force,
            "energy_unit_j": scales.energy,
            "time_unit_s": scales.time,
        },
        "regime_codes": REGIME_CODES,
    }


def _without_key(tree: Any, key: str) -> Any:
    """Drop ``key`` from every mapping in a nested container."""
    if isinstance(tree, dict):
        return {k: _without_key(v, key) for k, v in tree.items() if k != key}
    if isinstance(tree, list):
        return [_without_key(v, key) for v in tree]
    return tree


def _jsonable(tree: Any) -> Any:
    if isinstance(tree, dict):
        return {str(k): _jsonable(v) for k, v in tree.items()}
    if isinstance(tree, list | tuple):
        return [_jsonable(v) for v in tree]
    if isinstance(tree, np.ndarray):
        return tree.tolist()
    if isinstance(tree, np.generic):
        return tree.item()
    if isinstance(tree, float) and not math.isfinite(tree):
        return str(tree)
    if tree is None or isinstance(tree, bool | int | float | str):
        return tree
    return repr(tree)


def _measured(obj: dict[str, Any], x: np.ndarray, dt: float) -> np.ndarray:
    """Sensor output [m] for true deflection ``x`` (dimensionless)."""
    y = obj["sensor"](x, x_ref=obj["free_amplitude"], dt=dt)
    return np.asarray(y, dtype=float) * obj["scales"].length


def _write_single(cfg: DictConfig, obj: dict[str, Any], path: Path, result: SimulationResult,
                  free: SimulationResult | None) -> dict[str, Any]:
    scales: Scales = obj["scales"]
    _check_trajectory(obj["force"], result.gap)
    si = result.to_si(scales)
    deflection = _measured(obj, result.deflection, result.dt)
    free_m = _measured(obj, free.deflection, free.dt) if free is not None else None
    lab = si["labels"]
    labels = None
    if cfg.labels:
        scalars = {k: (v if isinstance(v, str) else float(v)) for k, v in lab.items()}
        if "step_index" in result.meta:
            scalars["step_index"] = float(result.meta["step_index"])
            scalars["step_m"] = float(result.meta["step"]) * scales.length
        labels = Labels(
            si["force_n"], modal_m=si["modal_m"], model=_model_json(cfg, obj), effect="none",
            scalars=scalars,
            extra={"tip_sample_gap_m": result.gap * scales.length,
                   "contact": result.contact.astype(float)})
    trace = Trace(
        deflection, sample_rate_hz=float(si["sample_rate_hz"]),
        drive_frequency_hz=float(si["drive_frequency_hz"]), gap_m=si["gap_m"],
        drive_phase_rad=float(si["drive_phase_rad"]), segment=si["segment"],
        free_deflection_m=free_m, labels=labels, **_calibration(cfg, obj))
    write_trace(trace, path)
    return {
        "n_points": 1, "n_samples": trace.n_samples,
        "amplitude_m": float(lab["amplitude_m"]),
        "contact_fraction": float(lab["contact_fraction"]),
        "dissipated_energy_j": float(lab["dissipated_energy_j"]),
        "peak_force_n": float(np.max(si["force_n"])),
        "coupling_strength": float(lab["coupling_strength"]),
        "regime": str(lab["regime"]),
    }


def _write_curve(cfg: DictConfig, obj: dict[str, Any], path: Path,
                 result: SimulationResult) -> dict[str, Any]:
    """A lock-in curve: amplitude, phase, piezo position, segment (no deflection)."""
    trace, summary = curve_trace(result, obj["scales"], _calibration(cfg, obj),
                                 model=_model_json(cfg, obj) if cfg.labels else None)
    write_trace(trace, path)
    return summary


def _rows_metrics(rows: dict[str, Any], regimes: list[str], *, n_points: int,
                  n_samples: int) -> dict[str, Any]:
    """Summary metrics of a file of rows (sweep points or set-points): largest amplitude,
    peak force and coupling, mean contact fraction and dissipation, most common regime."""
    return {
        "n_points": n_points, "n_samples": n_samples,
        "amplitude_m": float(np.max(rows["amplitude_m"])),
        "contact_fraction": float(np.mean(rows["contact_fraction"])),
        "dissipated_energy_j": float(np.mean(rows["dissipated_energy_j"])),
        "peak_force_n": float(np.max(rows["peak_force_n"])),
        "coupling_strength": float(np.max(rows["coupling_strength"])),
        "regime": collections.Counter(regimes).most_common(1)[0][0],
    }


def _write_sweep(cfg: DictConfig, obj: dict[str, Any], path: Path,
                 free: SimulationResult | None, bar: Any) -> dict[str, Any]:
    """Stream the sweep: each point goes through the sensor and into its row on disk."""
    sweep: Sweep = obj["scenario"]
    scales: Scales = obj["scales"]
    system: System = obj["system"]
    ell, f_unit = scales.length, scales.force
    n_rows, n = sweep.n_rows, sweep.samples_per_point
    free_m = _measured(obj, free.deflection, free.dt) if free is not None else None
    label_args: dict[str, Any] = {}
    if cfg.labels:
        label_args = {"n_modes": system.n_modes, "model": _model_json(cfg, obj)}
    rows: dict[str, np.ndarray] = collections.defaultdict(lambda: np.full(n_rows, np.nan))
    regimes: list[str] = []
    with TraceWriter(
        path, n_samples=n, n_points=n_rows,
        sample_rate_hz=scales.resonance_frequency * sweep.samples_per_period,
        drive_frequency_hz=sweep.row_omegas() * scales.resonance_frequency,
        gap_m=sweep.gap * ell, free_deflection_m=free_m, **_calibration(cfg, obj), **label_args,
    ) as writer:
        for point in sweep.iter_points(system, progress=bar):
            _check_trajectory(obj["force"], point.gap)
            y = _measured(obj, point.q.sum(axis=0), sweep.dt)
            lab = si_labels(point.labels, scales)
            regime = str(lab.pop("regime"))
            regimes.append(regime)
            lab["regime_code"] = float(REGIME_CODES.get(regime, -1))
            lab["peak_force_n"] = float(np.max(point.force)) * f_unit
            for key in ("amplitude_m", "contact_fraction", "dissipated_energy_j",
                        "peak_force_n", "coupling_strength"):
                rows[key][point.row] = lab[key]
            phase = recorded_drive_phase(float(point.phase[0]), system, point.omega)
            if cfg.labels:
                writer.write_row(point.row, y, force_n=point.force * f_unit,
                                 modal_m=point.q * ell, scalars=lab, drive_phase_rad=phase)
            else:
                writer.write_row(point.row, y, drive_phase_rad=phase)
    return _rows_metrics(rows, regimes, n_points=n_rows, n_samples=n)


def _write_series(cfg: DictConfig, obj: dict[str, Any], path: Path, result: SimulationResult,
                  free: SimulationResult | None) -> dict[str, Any]:
    """Write a set-point series: one row per rest gap, per-row labels and drive phases."""
    scales: Scales = obj["scales"]
    ell = scales.length
    _check_trajectory(obj["force"], result.gap)
    si = result.to_si(scales)
    deflection = _measured(obj, result.deflection, result.dt)
    free_m = _measured(obj, free.deflection, free.dt) if free is not None else None
    lab = dict(si["labels"])
    regimes = [str(r) for r in lab.pop("regime")]
    rows = {k: np.asarray(v, dtype=float) for k, v in lab.items()}
    rows["regime_code"] = np.array([float(REGIME_CODES.get(r, -1)) for r in regimes])
    rows["peak_force_n"] = np.max(si["force_n"], axis=-1)
    labels = None
    if cfg.labels:
        labels = Labels(
            si["force_n"], modal_m=si["modal_m"], model=_model_json(cfg, obj), effect="none",
            scalars=rows,
            extra={"tip_sample_gap_m": result.gap * ell, "contact": result.contact.astype(float)})
    trace = Trace(
        deflection, sample_rate_hz=float(si["sample_rate_hz"]),
        drive_frequency_hz=float(si["drive_frequency_hz"]), gap_m=result.rest_gap[:, 0] * ell,
        drive_phase_rad=si["drive_phase_rad"], free_deflection_m=free_m, labels=labels,
        **_calibration(cfg, obj))
    write_trace(trace, path)
    return _rows_metrics(rows, regimes, n_points=trace.n_points, n_samples=trace.n_samples)


def _update_manifest(folder: Path) -> Path:
    """Rebuild the manifest until it lists every shard present (shards finish concurrently)."""
    for _ in range(10):
        before = sorted(p.name for p in folder.glob("*.h5"))
        manifest = write_manifest(folder)
        if sorted(p.name for p in folder.glob("*.h5")) == before:
            return manifest
    return manifest

