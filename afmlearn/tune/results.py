"""Results of a study: the best settings as a Hydra config, a summary table, a JSON record.

:func:`write_results` writes into ``<results_dir>/<study_name>/``

- ``best.yaml`` -- ``name``, ``direction``, ``best_value``, ``best_params`` (the layout of
  hydra-optuna-sweeper's ``optimization_results.yaml``),
- ``summary.json`` -- counts per state, best trial, wall time per trial, every trial's
  parameters, values and state,

and ``<results_dir>/experiment/<study_name>.yaml``: a ``# @package _global_`` config with the
best parameters (config groups as ``override /group: option`` in its defaults list). Any entry
point takes it with ``--config-dir <results_dir> ... +experiment=<study_name>`` (the option
before the overrides).
"""

from __future__ import annotations

import datetime
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import optuna
from omegaconf import OmegaConf
from optuna.trial import TrialState

from afmlearn.io import write_json
from afmlearn.io._atomic import atomic_path

__all__ = ["experiment_config", "summary", "summary_table", "write_results"]


def _strip(key: str) -> str:
    return key.lstrip("+~")


def experiment_config(params: Mapping[str, Any], *, groups: Iterable[str] = (),
                      header: str = "") -> str:
    """A ``# @package _global_`` Hydra config (YAML text) setting ``params``.

    Parameters
    ----------
    params : mapping of str to scalar
        Config path -> value (dotted paths become nested nodes).
    groups : iterable of str
        Paths that are config groups (``model``): set through the defaults list.
    header : str
        Comment lines put on top (without ``#``).
    """
    group_set = {_strip(g) for g in groups}
    nested: dict[str, Any] = {}
    overrides = []
    for key, value in params.items():
        path = _strip(key)
        if path in group_set:
            overrides.append({f"override /{path.replace('.', '/')}": value})
            continue
        node = nested
        *parents, leaf = path.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value
    doc: dict[str, Any] = {}
    if overrides:
        doc["defaults"] = overrides
    doc.update(nested)
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    return "\n".join(["# @package _global_", *lines, OmegaConf.to_yaml(OmegaConf.create(doc))])


def summary(study: optuna.Study) -> dict[str, Any]:
    """Counts per state, best trial and timing of ``study`` (JSON-ready)."""
    trials = study.get_trials(deepcopy=False)
    counts = {s.name.lower(): sum(t.state == s for t in trials) for s in TrialState}
    finished = (TrialState.COMPLETE, TrialState.PRUNED)
    times = [float(t.user_attrs["wall_time_s"]) for t in trials
             if t.state in finished and "wall_time_s" in t.user_attrs]
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    best = None
    if complete and len(study.directions) == 1:
        b = study.best_trial
        best = {"number": b.number, "value": b.value, "params": dict(b.params)}
    base = next((t for t in trials if t.user_attrs.get("baseline")), None)
    baseline = None if base is None else {"number": base.number, "state": base.state.name.lower(),
                                          "value": base.value, "params": dict(base.params)}
    return {
        "study_name": study.study_name,
        "baseline": baseline,
        "directions": [d.name.lower() for d in study.directions],
        "counts": counts,
        "best": best,
        "wall_time_per_trial_s": (sum(times) / len(times)) if times else math.nan,
        "trials": [{"number": t.number, "state": t.state.name.lower(), "values": t.values,
                    "params": dict(t.params),
                    "retry_of": t.system_attrs.get("failed_trial"),
                    "wall_time_s": t.user_attrs.get("wall_time_s")} for t in trials],
    }


def summary_table(study: optuna.Study, *, top: int = 10) -> str:
    """A plain-text table: counts per state, then the ``top`` best finished trials."""
    doc = summary(study)
    c = doc["counts"]
    lines = [f"study {doc['study_name']} ({', '.join(doc['directions'])}): "
             f"{c['complete']} complete, {c['pruned']} pruned, {c['fail']} failed, "
             f"{c['running']} running, {c['waiting']} waiting; "
             f"wall time per trial {doc['wall_time_per_trial_s']:.3g} s"]
    base = doc["baseline"]
    if base is not None and base["value"] is not None:
        lines.append(f"baseline (the config's own values): trial {base['number']}, "
                     f"value {base['value']:.6g}")
    complete = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))]
    if not complete or len(study.directions) != 1:
        return "\n".join(lines)
    sign = 1.0 if study.direction == optuna.study.StudyDirection.MINIMIZE else -1.0
    complete.sort(key=lambda t: sign * float(t.value))
    names = list(dict.fromkeys(k for t in complete for k in t.params))
    cells = [["#", "value", *names]]
    for t in complete[:top]:
        cells.append([str(t.number), f"{t.value:.6g}",
                      *(_cell(t.params.get(n)) for n in names)])
    widths = [max(len(r[i]) for r in cells) for i in range(len(cells[0]))]
    for i, row in enumerate(cells):
        lines.append("  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)))
        if i == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return "" if value is None else str(value)


def _write_text(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path


def write_results(study: optuna.Study, *, results_dir: str | Path, groups: Iterable[str] = (),
                  ) -> dict[str, Path]:
    """Write ``best.yaml``, ``summary.json`` and the experiment config (see the module doc).

    Returns
    -------
    dict of str to Path
        ``best``, ``summary``, ``experiment`` (the last two only with a complete trial).
    """
    root = Path(results_dir)
    out = root / study.study_name
    out.mkdir(parents=True, exist_ok=True)
    files = {"summary": write_json(out / "summary.json", summary(study))}
    complete = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    if not complete or len(study.directions) != 1:
        return files
    best = study.best_trial
    record = {"name": "optuna", "study_name": study.study_name,
              "direction": study.direction.name.lower(), "best_value": best.value,
              "best_trial": best.number, "best_params": dict(best.params)}
    files["best"] = _write_text(out / "best.yaml", OmegaConf.to_yaml(OmegaConf.create(record)))
    stamp = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    header = (f"Best settings of Optuna study {study.study_name!r} (trial {best.number}, "
              f"value {best.value:.6g}, {len(complete)} complete trials), written {stamp}.\n"
              f"Use: python scripts/<entry>.py --config-dir {root} <overrides> "
              f"+experiment={study.study_name}")
    files["experiment"] = _write_text(root / "experiment" / f"{study.study_name}.yaml",
                                      experiment_config(best.params, groups=groups,
                                                        header=header))
    return files
