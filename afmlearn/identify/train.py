"""Training of the force identifier on the standard models (lightning-hydra-template style).

:func:`train` is the one function behind ``scripts/train_sindy.py``. For every scenario of
``cfg.train.scenarios`` (default steady state and a transient step in topography) it

1. simulates a labelled trace with the project's simulator config (:func:`afmlearn.simulate`,
   the same groups as ``conf/simulate.yaml``: cantilever, force, excitation, sensor and the
   scenario node ``cfg.scenarios.<name>``),
2. identifies it with the ``cfg.identifier`` node (a :class:`ForceIdentifier`), passing the true
   force (read from the file's labels: training may read them) so the Pareto front gets its
   force axis,
3. scores the result against the truth (``afmlearn.metrics``, ``design.md`` section 4): force
   accuracy on the whole trace, in repulsion, in attraction and near ``a0``; held-out state
   accuracy; coefficient errors of the mapped terms; interaction exponent; lever ``K``, ``D``,
   ``B``; selected vs true terms,

and writes into the run folder: ``metrics.json`` (every scenario) and per scenario
``<name>/trace.h5``, ``<name>/model.json`` (reloadable), ``<name>/result.json`` and the figures
``pareto.png``, ``coefficients.png`` (vs truth), ``orbit.png`` and ``force.png`` (vs truth).

True terms (simulator parameters -> library terms, ``F_ts > 0`` repulsive)
-------------------------------------------------------------------------
``dmt``, ``jkr``: ``z^-2`` coefficient ``-vdw`` (the library's ``z^-n`` is held at ``a0`` in
contact, as the simulator's tail), ``delta^p`` coefficient ``stiffness``, exponent ``p``.
``dmt_visco``: also ``delta^q delta'`` with coefficient ``viscosity``. ``expdamp``:
``exp(-z/z_b) z'`` with coefficient ``-coefficient``. ``lj``: ``z^-8`` coefficient
``repulsion``, ``z^-2`` coefficient ``-attraction``. ``ForceSum`` combines its terms. Other
models (e.g. hysteretic JKR, electrostatics) get force and state metrics only.

Coefficients are compared in SI units (:meth:`IdentifiedModel.si_terms`), which do not depend on
the length unit: a transient trace's ``L_ref`` (its mean rest gap) differs from the simulator's
(``cantilever.gap_m``). An identified term is matched to a true one of the same kind: same
inverse power ``n``; nearest exponent within ``EXPONENT_TOLERANCE`` (0.25) for ``delta^p`` (the
exponent error is reported separately) and, with the same rate power, for ``delta^p delta'^l``;
nearest SI decay length for ``exp(-z/z_b) z'``. Unmatched true terms count as missing (relative
error 1), unmatched identified terms as spurious.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf, open_dict

from afmlearn.io import read_trace
from afmlearn.metrics import coefficient_errors, force_accuracy, nrmse
from afmlearn.preprocess import calibrate, check_trace
from afmlearn.simulate import simulate
from simulator import Scales

from .identifier import ForceIdentifier
from .infer import jsonable, result_record, write_json
from .library import (
    AFMLibrary,
    ExponentialDamping,
    Indentation,
    IndentationRate,
    InversePower,
)
from .model import IdentifiedModel

__all__ = ["train", "true_model", "match_terms", "score", "EXPONENT_TOLERANCE"]

log = logging.getLogger(__name__)

#: largest exponent difference for which an identified ``delta^p`` (``delta^p delta'^l``) term
#: is compared with the true one; beyond it the coefficients have incomparable units and the
#: term counts as missing (true) and spurious (identified)
EXPONENT_TOLERANCE = 0.25


# ---------------------------------------------------------------------------- public API
def train(cfg: DictConfig, *, figures: Callable[..., dict[str, str]] | None = None
          ) -> tuple[dict[str, float], dict[str, Any]]:
    """Simulate, identify and score every scenario of ``cfg.train.scenarios``.

    Parameters
    ----------
    cfg : omegaconf.DictConfig
        Composed from ``conf/train_sindy.yaml`` (left unchanged).
    figures : callable, optional
        ``figures(identifier, calibrated, folder, *, truth_si, true_force) -> {name: path}``
        (e.g. :func:`afmlearn.plots.identify.training_figures`, passed by the script; this
        module never imports the plots); skipped when ``train.figures`` is false.

    Returns
    -------
    metrics : dict of str to float
        Flat ``"<scenario>/<name>"`` numbers: ``force_accuracy_whole``, ``_repulsive``,
        ``_attractive``, ``_near_a0``, ``force_nrmse``, ``state_accuracy``,
        ``coef_max_rel_error``, ``coef_mean_rel_error``, ``exponent_error``,
        ``stiffness_error``, ``damping_rel_error``, ``drive_rel_error``, ``support_exact``
        (1/0), ``n_terms``, ``runtime_s``; NaN where undefined.
    objects : dict
        ``cfg``, ``output_dir`` (Path), ``metrics_path``, and ``runs``: per scenario
        ``identifier`` (fitted), ``truth`` (:class:`IdentifiedModel` of the true terms or
        None), ``record`` (the nested metrics of ``metrics.json``), ``trace`` (path),
        ``simulation`` (metrics of :func:`afmlearn.simulate.simulate`), ``files``.

    Raises
    ------
    ValueError
        Bad settings (unknown scenario, missing config node), naming the key.
    """
    t0 = time.perf_counter()
    cfg = _checked(cfg)
    out = _output_dir(cfg)
    out.mkdir(parents=True, exist_ok=True)
    if not OmegaConf.select(cfg, "train.figures", default=True):
        figures = None
    flat: dict[str, float] = {}
    records: dict[str, Any] = {}
    runs: dict[str, Any] = {}
    for name in cfg.train.scenarios:
        log.info("scenario %s: simulating", name)
        run = _run_scenario(cfg, str(name), out / str(name), figures=figures)
        runs[str(name)] = run
        records[str(name)] = run["record"]
        for key, value in _flat(run["record"]).items():
            flat[f"{name}/{key}"] = value
    doc = {
        "force": OmegaConf.select(cfg, "force._target_"),
        "noise_level": float(OmegaConf.select(cfg, "noise.level", default=0.0)),
        "seed": int(cfg.seed),
        "scenarios": records,
        "runtime_s": time.perf_counter() - t0,
        "config": OmegaConf.to_container(cfg, resolve=True),
    }
    metrics_path = write_json(out / "metrics.json", doc)
    flat["runtime_s"] = doc["runtime_s"]
    return flat, {"cfg": cfg, "output_dir": out, "metrics_path": metrics_path, "runs": runs}


# ---------------------------------------------------------------------------- config
def _checked(cfg: DictConfig) -> DictConfig:
    if not isinstance(cfg, DictConfig):
        raise ValueError(f"cfg must be an omegaconf DictConfig, got {type(cfg).__name__}")
    cfg = copy.deepcopy(cfg)
    for key in ("identifier", "scenarios", "train"):
        if key not in cfg:
            raise ValueError(f"cfg: missing config node {key!r} (compose conf/train_sindy.yaml)")
    names = list(cfg.train.get("scenarios") or [])
    if not names:
        raise ValueError("train.scenarios must list at least one scenario, got []")
    for name in names:
        if name not in cfg.scenarios:
            raise ValueError(f"train.scenarios: {name!r} has no node scenarios.{name} "
                             f"(available: {sorted(cfg.scenarios)})")
    return cfg


def _output_dir(cfg: DictConfig) -> Path:
    """``cfg.output_dir``, else the Hydra run folder."""
    value = cfg.get("output_dir")
    if value:
        return Path(str(value))
    try:
        from hydra.core.hydra_config import HydraConfig

        return Path(HydraConfig.get().runtime.output_dir)
    except ValueError:
        raise ValueError("output_dir must be set when train() runs outside a Hydra "
                         "application") from None


def _simulation_cfg(cfg: DictConfig, name: str, trace_path: Path) -> DictConfig:
    """The simulate() config of one scenario: ``scenario = scenarios.<name>``, labels on."""
    sim = copy.deepcopy(cfg)
    with open_dict(sim):
        sim.scenario = sim.scenarios[name]
        sim.output = str(trace_path)
        sim.labels = True
        for key in ("scenarios", "train", "identifier", "output_dir"):
            sim.pop(key, None)
    return sim


# ---------------------------------------------------------------------------- one scenario
def _run_scenario(cfg: DictConfig, name: str, folder: Path, *,
                  figures: Callable[..., dict[str, str]] | None) -> dict[str, Any]:
    t0 = time.perf_counter()
    folder.mkdir(parents=True, exist_ok=True)
    sim_metrics, _ = simulate(_simulation_cfg(cfg, name, folder / "trace.h5"))
    path = Path(sim_metrics["output"])
    trace = read_trace(path)
    labels = read_trace(path, labels=True).labels
    assert labels is not None
    check_trace(trace)
    cal = calibrate(trace)
    sc = cal.scales
    true_force = np.asarray(labels.force_n, float) / sc.force
    ide = instantiate(cfg.identifier, _convert_="all")
    if not isinstance(ide, ForceIdentifier):
        raise ValueError(f"identifier must build a ForceIdentifier, got {type(ide).__name__}")
    log.info("scenario %s: identifying %d samples", name, cal.n_samples)
    ide.fit(cal, true_force=true_force)
    truth = true_model(labels.model, omega=cal.omega, quality_factor=cal.quality_factor)
    record = score(ide, truth, force_n=np.asarray(labels.force_n, float),
                   gap_m=np.asarray(labels.extra["tip_sample_gap_m"], float),
                   model_json=labels.model, scales=sc)
    record["simulation"] = {k: v for k, v in sim_metrics.items() if k != "output"}
    files = {"trace": str(path), "model": str(ide.model_.save(folder / "model.json"))}
    if figures is not None:
        files.update(figures(ide, cal, folder, truth_si=record["truth_si_by_est"],
                             true_force=true_force))
    record["runtime_s"] = time.perf_counter() - t0
    result = result_record(ide, cal, input_path=path, row=None, runtime_s=record["runtime_s"])
    files["result"] = str(write_json(folder / "result.json", result))
    record["files"] = files
    return {"identifier": ide, "truth": truth, "record": record, "trace": path,
            "simulation": sim_metrics, "files": files, "calibrated": cal}


# ---------------------------------------------------------------------------- truth
def _true_terms(force: Mapping[str, Any]) -> list[tuple[Any, float]]:
    """(library term, dimensionless coefficient) pairs of a simulator force record."""
    name = force.get("model")
    p = force.get("parameters", {})
    if "terms" in p:
        return [tt for sub in p["terms"] for tt in _true_terms(sub)]
    if name in ("dmt", "jkr", "dmt_visco"):
        out: list[tuple[Any, float]] = [(Indentation(float(p["exponent"])), float(p["stiffness"]))]
        if float(p["vdw"]) > 0:
            out.insert(0, (InversePower(2.0), -float(p["vdw"])))
        if name == "dmt_visco" and float(p["viscosity"]) > 0:
            out.append((IndentationRate(float(p["viscosity_exponent"]), 1),
                        float(p["viscosity"])))
        return out
    if name == "expdamp":
        return [(ExponentialDamping(float(p["decay_length"])), -float(p["coefficient"]))]
    if name == "lj":
        return [(InversePower(8.0), float(p["repulsion"])),
                (InversePower(2.0), -float(p["attraction"]))]
    raise KeyError(name)


def _true_a0(force: Mapping[str, Any]) -> float | None:
    """Contact onset / simulator length of a force record; LJ: the zero of the force."""
    p = force.get("parameters", {})
    if "a0" in p:
        return float(p["a0"])
    if force.get("model") == "lj" and float(p.get("attraction", 0)) > 0:
        return (float(p["repulsion"]) / float(p["attraction"])) ** (1 / 6)
    for sub in p.get("terms", []):
        a0 = _true_a0(sub)
        if a0 is not None:
            return a0
    return None


def true_model(model_json: Mapping[str, Any], *, omega: float,
               quality_factor: float) -> IdentifiedModel | None:
    """The simulator's force as an :class:`IdentifiedModel` in the simulator's units.

    Parameters
    ----------
    model_json : mapping
        ``labels.model`` of a simulated trace (``force``, ``excitation``, ``calibration``).
    omega, quality_factor : float
        Drive frequency / f0 and Q (for the lever part of the model).

    Returns
    -------
    IdentifiedModel or None
        None when the force model has no library mapping (see the module docstring).
    """
    try:
        terms = _true_terms(model_json["force"])
    except KeyError:
        return None
    cal = model_json["calibration"]
    scales = Scales(spring_constant=float(cal["spring_constant_n_per_m"]),
                    resonance_frequency=float(cal["resonance_frequency_hz"]),
                    length=float(cal["length_m"]))
    exc = model_json.get("excitation", {})
    drive = float(exc.get("amplitude", math.nan)) if exc.get("kind") == "tip" else math.nan
    a0 = _true_a0(model_json["force"]) or 1.0
    return IdentifiedModel(library=AFMLibrary([t for t, _ in terms]),
                           coefficients=np.array([c for _, c in terms]), stiffness=1.0,
                           damping=1.0 / quality_factor, drive_amplitude=drive, drive_phase=0.0,
                           omega=omega, a0=a0, gap=1.0, scales=scales,
                           info={"source": "simulator labels"})


def match_terms(est: IdentifiedModel, truth: IdentifiedModel) -> dict[int, int]:
    """Map identified term indices to true term indices (see the module docstring)."""
    taken: set[int] = set()
    out: dict[int, int] = {}
    l_est, l_true = est.scales.length, truth.scales.length
    for j, t in enumerate(truth.library.terms):
        best, dist = None, math.inf
        for i, e in enumerate(est.library.terms):
            if i in taken or type(e) is not type(t):
                continue
            if isinstance(t, InversePower):
                d = abs(e.n - t.n)
                ok = d < 0.5
            elif isinstance(t, Indentation):
                d = abs(e.p - t.p)
                ok = d <= EXPONENT_TOLERANCE
            elif isinstance(t, IndentationRate):
                d = abs(e.p - t.p)
                ok = e.l == t.l and d <= EXPONENT_TOLERANCE
            elif isinstance(t, ExponentialDamping):
                d = abs(math.log(e.decay_length * l_est / (t.decay_length * l_true)))
                ok = True
            else:
                continue
            if ok and d < dist:
                best, dist = i, d
        if best is not None:
            out[best] = j
            taken.add(best)
    return out


# ---------------------------------------------------------------------------- metrics
def score(ide: ForceIdentifier, truth: IdentifiedModel | None, *, force_n: np.ndarray,
          gap_m: np.ndarray, model_json: Mapping[str, Any], scales: Scales) -> dict[str, Any]:
    """Nested metrics of one identification against the simulator's truth.

    Parameters
    ----------
    ide : ForceIdentifier
        Fitted.
    truth : IdentifiedModel or None
        From :func:`true_model`.
    force_n : ndarray, shape (n,)
        True force [N].
    gap_m : ndarray, shape (n,)
        True instantaneous gap [m].
    model_json : mapping
        ``labels.model``.
    scales : Scales
        The identifier's units (``k``, ``f0``, ``L_ref``).

    Returns
    -------
    dict
        ``force_accuracy`` (design.md section 4 regions, SI), ``force_nrmse``,
        ``state_accuracy``, ``coefficients`` (:func:`afmlearn.metrics.coefficient_errors` on
        SI coefficients keyed by true term names), ``exponent`` (true, identified, error),
        ``lever`` errors, ``terms`` (selected, true, missing, spurious, support_exact),
        ``equation``, ``summary``, ``truth_si_by_est`` (true SI coefficients keyed by the
        identified names, for figures).
    """
    model = ide.model_
    f_pred = np.asarray(ide.force_, float) * scales.force
    a0_true = _true_a0(model_json.get("force", {}))
    length_sim = float(model_json["calibration"]["length_m"])
    rec: dict[str, Any] = {"equation": model.equation(), "equation_si": model.equation_si(),
                           "summary": jsonable(ide.summary_), "warnings": list(ide.warnings_)}
    if a0_true is not None:
        rec["force_accuracy"] = force_accuracy(f_pred, force_n, gap_m, a0_true * length_sim)
    ok = np.isfinite(f_pred)
    rec["force_nrmse"] = nrmse(f_pred[ok], force_n[ok]) if ok.any() else math.nan
    rec["state_accuracy"] = float(ide.summary_.get("state_accuracy_heldout", math.nan))
    est_si = model.si_terms()
    selected = [t["term"] for t in est_si]
    rec["terms"] = {"selected": selected, "n_terms": len(selected)}
    rec["truth_si_by_est"] = {}
    if truth is None:
        rec["terms"].update({"true": None, "support_exact": None})
        return rec
    true_si = truth.si_terms()
    true_names = [t["term"] for t in true_si]
    pairs = match_terms(model, truth)
    est_by_true = {}
    for i, t in enumerate(est_si):
        key = true_names[pairs[i]] if i in pairs else t["term"]
        est_by_true[key] = t["coefficient"]
        if i in pairs:
            rec["truth_si_by_est"][t["term"]] = true_si[pairs[i]]["coefficient"]
    for j, t in enumerate(true_si):
        if j not in pairs.values():
            rec["truth_si_by_est"][t["term"]] = t["coefficient"]
    truth_by_name = {t["term"]: t["coefficient"] for t in true_si}
    rec["coefficients"] = coefficient_errors(est_by_true, truth_by_name)
    rec["coefficients"]["units"] = {t["term"]: t["unit"] for t in true_si}
    missing = [n for n in true_names if n not in est_by_true]
    spurious = [est_si[i]["term"] for i in range(len(est_si)) if i not in pairs]
    rec["terms"].update({"true": true_names, "missing": missing, "spurious": spurious,
                         "support_exact": not missing and not spurious})
    p_true = next((float(t.p) for t in truth.library.terms if isinstance(t, Indentation)), None)
    p_est = ide.summary_.get("interaction_exponent")
    rec["exponent"] = {"true": p_true, "identified": p_est,
                       "error": (abs(float(p_est) - p_true)
                                 if p_true is not None and p_est is not None else None)}
    # lever: K and D are unit free; B compared in newtons (the units' lengths differ)
    b_true = truth.drive_amplitude * truth.scales.force
    b_est = model.drive_amplitude * scales.force
    rec["lever"] = {
        "stiffness": model.stiffness, "stiffness_error": abs(model.stiffness - 1.0),
        "damping": model.damping, "damping_true": truth.damping,
        "damping_rel_error": abs(model.damping - truth.damping) / truth.damping,
        "drive_n": b_est, "drive_true_n": b_true,
        "drive_rel_error": abs(b_est - b_true) / abs(b_true) if math.isfinite(b_true) else None,
    }
    return rec


def _flat(rec: Mapping[str, Any]) -> dict[str, float]:
    """The scalar headline numbers of one scenario record (NaN where undefined)."""

    def num(x: Any) -> float:
        return float(x) if isinstance(x, int | float) and x is not None else math.nan

    fa = rec.get("force_accuracy", {})
    coefs = rec.get("coefficients", {})
    lever = rec.get("lever", {})
    exact = rec["terms"].get("support_exact")
    return {
        "force_accuracy_whole": num(fa.get("whole", {}).get("accuracy")),
        "force_accuracy_repulsive": num(fa.get("repulsive", {}).get("accuracy")),
        "force_accuracy_attractive": num(fa.get("attractive", {}).get("accuracy")),
        "force_accuracy_near_a0": num(fa.get("near_a0", {}).get("accuracy")),
        "force_nrmse": num(rec.get("force_nrmse")),
        "state_accuracy": num(rec.get("state_accuracy")),
        "coef_max_rel_error": num(coefs.get("max_rel_error")),
        "coef_mean_rel_error": num(coefs.get("mean_rel_error")),
        "exponent_error": num(rec.get("exponent", {}).get("error")),
        "stiffness_error": num(lever.get("stiffness_error")),
        "damping_rel_error": num(lever.get("damping_rel_error")),
        "drive_rel_error": num(lever.get("drive_rel_error")),
        "support_exact": math.nan if exact is None else float(bool(exact)),
        "n_terms": float(rec["terms"]["n_terms"]),
        "runtime_s": num(rec.get("runtime_s")),
    }
