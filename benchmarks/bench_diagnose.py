"""Diagnosis benchmark: hidden-effect traces, confusion matrix, gain and runtime per cause.

Protocol (issue 5):

1. **Null calibration** (``--calibrate``): ``--null`` traces without any effect per setting
   (seeds disjoint from step 2) are diagnosed; the per-cause significance thresholds hold the
   family-wise false-cause rate at ``--family-rate`` (5 %, Bonferroni over the 7 causes:
   each extension's empirical null quantile, at least the chi-square point of its parameter
   count) and are written to ``afmlearn/diagnose/null_calibration.json``.
2. **Evaluation**: ``--per-cause`` traces per cause (7 effects and none) per setting, each with
   its own random cantilever and sample parameters (the cause is fixed per row of the matrix,
   everything else is drawn). Settings default to the issue's: 1,000 samples per period at
   0.5 % noise and 200 samples per period at 1 % noise, 300 periods each.

Raw per-candidate statistics go to a JSON-lines file (resumable: finished traces are skipped
when the command is run again); the confusion matrix is computed from them with the shipped
calibration. Run: ``python benchmarks/bench_diagnose.py --calibrate`` (about an hour on 2 cores).

Set-point series (``--series``, issue 12) run in pieces: one JSON line per (draw, variant) in
``series.jsonl``, each naming the commit it was measured on (``--snapshot COMMIT`` runs a
``git archive`` copy of that commit, so others' uncommitted edits in the shared tree cannot
leak in). Select with ``--causes``, ``--first``/``--per-cause``, ``--pairs`` and
``--variants`` (the 4- and 1-point variants are rows of the same 8-point draw; ``none`` = the
same file with the drive phase dropped); ``--since COMMIT`` re-runs records older than a
change; ``--report-only`` merges whatever is recorded and states per cell how many draws and
which commits it rests on. ``--oracle`` adds the true law's drop per draw (is the effect
visible at all?); ``--calibrate --keep-thresholds`` reports the false-cause rate on the
pooled null series. Two free amplitudes (issue 12): the variant ``2x4:phase`` diagnoses a
draw of ``hidden_series(..., free_amplitudes=2)`` (2 free amplitudes x 4 set-points, both
files as one experiment) and ``twin:phase`` the same draw recorded at its first amplitude
only (8 set-points; same tip, law, set-points, phases, noise seeds); ``--calibrate --design
two`` derives their thresholds (section ``"series_amplitudes"``). Example (one niced
single-threaded process)::

    nice -n 10 python benchmarks/bench_diagnose.py --series --settings 200:0.01 \\
        --causes electrostatic,none --per-cause 10 --pairs 0 --variants 8:phase \\
        --periods 30 --workers 1 --snapshot HEAD --no-doc
"""

from __future__ import annotations

import os
import re

os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # one process per core

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import multiprocessing as mp  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import final  # noqa: E402

import numpy as np  # noqa: E402
from _common import (  # noqa: E402
    ROOT,
    add_doc_flag,
    fmt,
    git_snapshot,
    machine_info,
    md_table,
    write_section,
)
from scipy import stats  # noqa: E402
from tqdm.auto import tqdm  # noqa: E402

#: a code snapshot (``--snapshot``) goes before the working tree, which _common put first
if os.environ.get("BENCH_DIAGNOSE_CODE"):
    sys.path.insert(0, os.environ["BENCH_DIAGNOSE_CODE"])

from afmlearn.diagnose import CAUSES, Diagnoser, NullCalibration  # noqa: E402
from afmlearn.diagnose.diagnoser import name_cause  # noqa: E402
from afmlearn.diagnose.synthetic import EFFECT_PAIRS, hidden_series, hidden_trace  # noqa: E402
from afmlearn.io import Experiment, read_trace  # noqa: E402

CALIBRATION = ROOT / "afmlearn" / "diagnose" / "null_calibration.json"
#: extension parameters (nonlinear + linear) per cause, for the chi-square floor
N_PARAMS = {"higher_mode": 3, "viscoelastic": 1, "long_range_damping": 2,
            "contact_geometry": 1, "adhesion_hysteresis": 2, "electrostatic": 2,
            "detector_nonlinearity": 2}


def _job(job: dict) -> dict:
    """Simulate one hidden-effect trace and diagnose it; the truth stays in this function."""
    t0 = time.perf_counter()
    rng = np.random.default_rng([job["seed"], job["set_id"], job["spp"], job["index"],
                                 CAUSES.index(job["cause"])])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "trace.h5"
        case = hidden_trace(rng, path, cause=job["cause"], samples_per_period=job["spp"],
                            n_periods=job["periods"], noise_level=job["noise"])
        t_sim = time.perf_counter() - t0
        trace = read_trace(path)              # no labels
        t1 = time.perf_counter()
        d = Diagnoser().fit(trace)
        t_diag = time.perf_counter() - t1
    return {**job, "case": case.to_dict(), "t_sim": t_sim, "t_diag": t_diag,
            "baseline_nrmse": d.baseline_nrmse_, "cause_found": d.cause_,
            "candidates": [{"cause": c.cause, "delta_chi2": c.delta_chi2, "gain": c.gain}
                           for c in d.candidates_]}


def _key(r: dict) -> tuple:
    return (r["set_id"], r["spp"], r["noise"], r["cause"], r["index"], r["seed"],
            r["periods"])


def run_jobs(jobs: list[dict], records: Path, workers: int, *, job=None, key=None,
             desc: str = "diagnose", accept=None) -> list[dict]:
    """Run the missing ``jobs`` (resumable: one JSON line each as it finishes, in ``records``)
    and return the record of every job that has one. ``job``/``key``: the worker function
    and the record key (default: one-record diagnoses); ``accept``: which stored records
    count as done (default all; a later line of the same key replaces an earlier one)."""
    job, key = job or _job, key or _key
    records.parent.mkdir(parents=True, exist_ok=True)
    done = {}
    if records.exists():
        for line in records.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if accept is None or accept(r):
                    done[key(r)] = r
    todo = [j for j in jobs if key(j) not in done]
    if todo:
        ctx = mp.get_context("spawn")
        with ctx.Pool(workers) as pool, open(records, "a") as f:
            for r in tqdm(pool.imap_unordered(job, todo), total=len(todo), desc=desc,
                          disable=None):
                f.write(json.dumps(r) + "\n")
                f.flush()
                done[key(r)] = r
    return [done[key(j)] for j in jobs if key(j) in done]


def calibrate(null_records: list[dict], family_rate: float) -> NullCalibration:
    """Per-cause thresholds for a family-wise false-cause rate ``family_rate`` (Bonferroni).

    Each extension is tested at level ``family_rate / n_causes``: its threshold is the
    ``1 - level`` quantile of its ``delta_chi2`` over the null traces (which holds the
    look-elsewhere effect of its grid search), and at least the chi-square ``1 - level``
    point of its parameter count (what a nested likelihood-ratio test would use).
    """
    causes = [c["cause"] for c in null_records[0]["candidates"]]
    level = family_rate / len(causes)
    thr = {}
    for i, cause in enumerate(causes):
        d = np.array([r["candidates"][i]["delta_chi2"] for r in null_records])
        floor = float(stats.chi2.ppf(1 - level, N_PARAMS.get(cause, 1)))
        thr[cause] = round(max(float(np.quantile(d, 1 - level)), floor), 2)
    settings = sorted({(r["spp"], r["noise"]) for r in null_records})
    src = (f"bench_diagnose.py --calibrate: family-wise false-cause rate {family_rate:g} "
           f"(Bonferroni over {len(causes)} causes): per cause the {1 - level:.4f} quantile of "
           f"delta_chi2 over {len(null_records)} null traces (samples/period, noise "
           f"{settings}), at least the chi2 point of its parameter count")
    return NullCalibration(thresholds=thr, min_gain=0.05, source=src)


def null_count(source: str) -> int:
    """The number of null traces a calibration's ``source`` text says it rests on (0 when it
    does not say); the text also says "over 7 causes", which is not it."""
    m = re.search(r"over (\d+) null traces", source)
    return int(m.group(1)) if m else 0


def evaluate(records: list[dict], calib: NullCalibration) -> dict:
    """Confusion matrix and per-cause figures with ``calib``."""
    causes = list(CAUSES)
    found_causes = [c["cause"] for c in records[0]["candidates"]]
    conf = np.zeros((len(causes), len(causes)), int)
    gains: dict[str, list[float]] = {c: [] for c in causes}
    times = []
    by_gain = 0
    for r in records:
        d = [c["delta_chi2"] for c in r["candidates"]]
        g = [c["gain"] for c in r["candidates"]]
        t = [calib.threshold(c) for c in found_causes]
        idx, _ = name_cause(d, g, t, calib.min_gain)
        found = "none" if idx is None else found_causes[idx]
        conf[causes.index(r["cause"]), causes.index(found)] += 1
        if r["cause"] != "none" and found == r["cause"]:
            gains[r["cause"]].append(g[idx])
        times.append(r["t_diag"])
        # the rule the issue first asked for, for comparison: the largest significant gain
        sig = [i for i in range(len(d)) if d[i] > t[i] and g[i] > calib.min_gain]
        alt = found_causes[max(sig, key=lambda i: g[i])] if sig else "none"
        by_gain += alt == r["cause"]
    return {"confusion": conf, "gains": gains, "times": np.array(times),
            "accuracy_by_gain": by_gain / max(len(records), 1)}


def section(results: dict[tuple, dict], calib: NullCalibration, n_null: int) -> str:
    causes = list(CAUSES)
    short = {"none": "none", "higher_mode": "mode", "viscoelastic": "visco",
             "long_range_damping": "lr-damp", "contact_geometry": "geom",
             "adhesion_hysteresis": "hyst", "electrostatic": "elec",
             "detector_nonlinearity": "detect"}
    out = [f"Hidden-effect traces: per row one cause switched on (``none``: the baseline "
           f"itself), every other parameter drawn at random (Q 150-450, free amplitude "
           f"1.2-1.8 gaps, tip radius 5-20 nm, Hamaker 0.5-2e-19 J, E* 1-5 GPa, a0 "
           f"0.2-0.4 nm; effect strengths in `afmlearn/diagnose/synthetic.py`), 300 "
           f"periods, tapping orbits only. Diagnosis never sees the labels. Thresholds: "
           f"{calib.source} ({n_null} null traces, seeds disjoint from these)."]
    for (spp, noise), res in results.items():
        conf = res["confusion"]
        rows = []
        for i, c in enumerate(causes):
            n = conf[i].sum()
            acc = conf[i, i] / n if n else math.nan
            g = res["gains"][c]
            rows.append([c, *[str(v) for v in conf[i]], f"{100 * acc:.0f} %",
                         fmt(float(np.median(g))) if g else "-"])
        tot = conf.sum()
        null_fp = 1 - conf[0, 0] / max(conf[0].sum(), 1)
        eff = [g for c in causes[1:] for g in res["gains"][c]]
        t = res["times"]
        out.append(
            f"\n### {spp} samples/period, {100 * noise:g} % noise\n\n"
            + md_table(["true \\ named", *[short[c] for c in causes], "correct",
                        "median gain"], rows)
            + f"\n\nOverall {100 * np.trace(conf) / tot:.1f} % correct; false cause on "
              f"{100 * null_fp:.0f} % of null traces; median gain when the effect is "
              f"named correctly {fmt(float(np.median(eff))) if eff else '-'}; diagnosis "
              f"time median {t.mean() if t.size == 0 else np.median(t):.1f} s, max "
              f"{t.max():.1f} s per 300-period trace (one core each, two traces at a time). "
              f"Naming by the largest significant held-out gain instead of the largest "
              f"penalised evidence: {100 * res['accuracy_by_gain']:.1f} % correct overall.")
    return "\n".join(out)


# ---------------------------------------------------------------------- set-point series
#: rows of an 8-point series (set-points decreasing) kept for each variant: every row, every
#: other one, and the deepest (smallest gap, always tapping) as the single orbit
SUBSETS = {8: list(range(8)), 4: [1, 3, 5, 7], 1: [7]}


def _design(r: dict) -> str:
    """A record's experiment design: ``one`` free amplitude (8 rows; the records before the
    design existed), ``two`` (2 free amplitudes x 4 set-points, G's generator) or ``twin``
    (the two-amplitude draw recorded at its first free amplitude only, 8 rows)."""
    return r.get("design", "one")


def _variant(r: dict) -> tuple[int, bool, str]:
    return r["n_points"], r["phase"], _design(r)


def _series_file(job: dict, folder: Path) -> tuple[Path, dict]:
    """The draw's file (simulated once, shared by its variants; neutral name) and its case;
    for the ``two`` design the folder of its two files (``synthetic.series_files``), for
    ``twin`` the one-amplitude file of the same two-amplitude draw."""
    key = json.dumps([job["set_id"], job["spp"], job["noise"], job["cause"], job["index"],
                      job["seed"], job["periods"]])
    path = folder / (hashlib.sha1(key.encode()).hexdigest()[:16] + ".h5")
    rng = np.random.default_rng([job["seed"], job["set_id"], job["spp"], job["index"],
                                 _cause_code(job["cause"])])
    if _design(job) != "one":
        return _two_amplitude_file(job, path.with_suffix(""), rng)
    if not path.exists():
        case = hidden_series(rng, path, causes=job["cause"], n_points=8,
                             samples_per_period=job["spp"], n_periods=job["periods"],
                             noise_level=job["noise"])
        return path, case.to_dict()
    return path, dict(read_trace(path, labels=True).labels.model["case"])


def _two_amplitude_file(job: dict, folder: Path, rng: np.random.Generator
                        ) -> tuple[Path, dict]:
    """The two-amplitude draw in ``folder`` (made once) and, for ``twin``, its one-amplitude
    twin ``<folder>-twin.h5`` (same tip, law, set-points, drive phases and noise seeds; the
    twin is not re-checked for tapping: the one-amplitude experiment's physics)."""
    from afmlearn.diagnose.synthetic import SeriesCase, hidden_series, simulate_series

    opts = {"samples_per_period": job["spp"], "n_periods": job["periods"],
            "noise_level": job["noise"]}
    if not (folder / "amplitude-1.h5").exists():
        case = hidden_series(rng, folder, causes=job["cause"], n_points=8, free_amplitudes=2,
                             **opts).to_dict()
    else:
        case = dict(read_trace(folder / "amplitude-0.h5", labels=True).labels.model["case"])
    if _design(job) == "two":
        return folder, case
    twin = folder.with_name(folder.name + "-twin.h5")
    one = SeriesCase.from_dict(case).one_amplitude()
    if not twin.exists():
        simulate_series(one, twin, **opts)
    return twin, one.to_dict()


def _cause_code(cause: str) -> int:
    return int(hashlib.sha1(cause.encode()).hexdigest()[:6], 16)


def code_version() -> str:
    """The commit of the ``afmlearn`` code this process imported.

    A snapshot made by ``--snapshot`` (``git archive`` of one commit, put first on
    ``PYTHONPATH``) carries a ``COMMIT`` file: its id, so records taken in a tree that other
    people edit still name the code they measured. Otherwise ``git rev-parse HEAD`` of the
    tree, with ``+dirty`` when ``afmlearn/`` or ``simulator/`` have uncommitted changes.
    """
    import afmlearn

    pkg_root = Path(afmlearn.__file__).resolve().parents[1]
    stamp = pkg_root / "COMMIT"
    if stamp.exists():
        return stamp.read_text().strip()
    try:
        head = subprocess.run(["git", "-C", str(pkg_root), "rev-parse", "--short=10", "HEAD"],
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(pkg_root), "status", "--porcelain",
                                "afmlearn", "simulator"], capture_output=True, text=True,
                               timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (head or "unknown") + ("+dirty" if dirty else "")


def _series_job(job: dict) -> dict:
    """Diagnose one variant (set-points, drive phase recorded or not) of one series draw."""
    folder = Path(job["files"])
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    try:
        path, case = _series_file(job, folder)
    except (FloatingPointError, RuntimeError) as err:   # a twin diverged / no tapping draw
        return {**job, "case": {}, "t_sim": time.perf_counter() - t0, "t_diag": 0.0,
                "commit": code_version(), "load": os.getloadavg()[0],
                "error": f"simulation: {type(err).__name__}: {err}", "cause_found": "error",
                "gain": 0.0, "causes_found": [], "exponent": None, "exponent_interval": None,
                "candidates": []}
    t_sim = time.perf_counter() - t0
    if _design(job) == "two":                           # one experiment of both files
        from afmlearn.diagnose.observation import read_experiment
        from afmlearn.diagnose.synthetic import series_files
        exp = read_experiment(series_files(path))       # no labels
    else:
        exp = Experiment.read(path)                     # no labels
    if not job["phase"]:
        exp = Experiment([dataclasses.replace(t, drive_phase_rad=None) for t in exp],
                         kind=exp.kind)
    exp = exp.subset(SUBSETS[job["n_points"]])
    t1, c1 = time.perf_counter(), time.process_time()
    try:
        d = Diagnoser().fit(exp if len(exp) > 1 else exp[0])
    except Exception as err:  # noqa: BLE001 -- a failed diagnosis is a result to report
        return {**job, "case": case, "t_sim": t_sim, "t_diag": time.perf_counter() - t1,
                "commit": code_version(), "load": os.getloadavg()[0],
                "error": f"{type(err).__name__}: {err}", "cause_found": "error", "gain": 0.0,
                "causes_found": [], "exponent": None, "exponent_interval": None,
                "candidates": []}
    t_diag = time.perf_counter() - t1
    ivl = getattr(d, "exponent_interval_", None)
    return {**job, "case": case, "t_sim": t_sim, "t_diag": t_diag,
            "t_cpu": time.process_time() - c1, "commit": code_version(),
            "load": os.getloadavg()[0],
            "baseline_nrmse": d.baseline_nrmse_, "extended_nrmse": d.extended_nrmse_,
            "cause_found": d.cause_, "gain": d.gain_,
            "causes_found": [{"cause": c.cause, "gain": float(c.gain)}
                             for c in (getattr(d, "causes_", None) or [])],
            "exponent": getattr(d, "exponent_", None),
            "exponent_interval": None if ivl is None else [float(ivl[0]), float(ivl[1])],
            "candidates": [{"cause": c.cause, "delta_chi2": c.delta_chi2, "gain": c.gain,
                            "threshold": c.threshold} for c in d.candidates_]}


def _series_key(r: dict) -> tuple:
    return (*_key(r), *_variant(r))


def run_series_jobs(jobs: list[dict], records: Path, workers: int,
                    since: str = "") -> list[dict]:
    """Run missing variant jobs (resumable, one JSON line each as it finishes); with
    ``since`` a stored record counts only when taken on that commit or a later one."""
    return run_jobs(jobs, records, workers, job=_series_job, key=_series_key,
                    desc="diagnose series", accept=_since(since) if since else None)


def _newer(a: str, b: str) -> bool:
    """Commit ``a`` (a record's, maybe marked) is a strict descendant of ``b``."""
    a, b = a.split()[0].split("+")[0], (b.split() or ["?"])[0].split("+")[0]
    if a == b or "?" in (a, b) or "unknown" in (a, b):
        return False
    return subprocess.run(["git", "-C", str(ROOT), "merge-base", "--is-ancestor", b, a],
                          capture_output=True, timeout=10).returncode == 0


def _since(commit: str):
    """Record filter: taken on ``commit`` or a descendant (never on a dirty tree)."""
    cache: dict[str, bool] = {}

    def ok(r: dict) -> bool:
        c = r.get("commit", "unknown")
        if c not in cache:
            cache[c] = ("+" not in c and c != "unknown" and subprocess.run(
                ["git", "-C", str(ROOT), "merge-base", "--is-ancestor", commit, c],
                capture_output=True, timeout=10).returncode == 0)
        return cache[c]
    return ok


def series_jobs(settings: list[tuple[int, float]], per_cause: int, pairs: int, periods: float,
                seed: int, files: Path, variants: list[tuple[int, bool, str]],
                causes: list[str] | None = None, first: int = 0) -> list[dict]:
    """Every variant of every draw, ordered draw by draw (partial runs compare like with
    like: all variants of the first draws of every cause come first). ``pairs`` draws per
    pair of effects cycle through :data:`EFFECT_PAIRS` (one pair per draw index); ``first``:
    the single-cause draws start at this index (the pairs always at 0)."""
    labels = list(CAUSES) if causes is None else list(causes)
    jobs = []
    for i in range(max(per_cause, pairs)):
        for spp, noise in settings:
            todo = labels if first <= i < per_cause else []
            if i < pairs:
                todo = [*todo, "+".join(EFFECT_PAIRS[(3 * i) % len(EFFECT_PAIRS)])]
            for c in todo:
                for n_points, phase, design in variants:
                    jobs.append({"set_id": 3, "spp": spp, "noise": noise, "cause": c,
                                 "index": i, "seed": seed, "periods": periods,
                                 "n_points": n_points, "phase": phase, "design": design,
                                 "files": str(files)})
    return jobs


def upper_bound(k: int, n: int, conf: float = 0.95) -> float:
    """One-sided ``conf`` Clopper--Pearson upper bound of a rate seen ``k`` times in ``n``."""
    return 1.0 if k >= n else float(stats.beta.ppf(conf, k + 1, n - k))


def interval(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Two-sided ``conf`` Clopper--Pearson interval of a share seen ``k`` times in ``n``."""
    a = (1 - conf) / 2
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k >= n else float(stats.beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def share(k: int, n: int) -> str:
    """``k/n = x %`` with its two-sided 95 % Clopper--Pearson interval in brackets."""
    lo, hi = interval(k, n)
    return f"{k}/{n} = {100 * k / n:.0f} % [{100 * lo:.0f}-{100 * hi:.0f}]"


def _found(r: dict) -> list[str]:
    return [x["cause"] for x in r["causes_found"]] or [r["cause_found"]]


def _hit(r: dict) -> bool:
    truth = r["cause"]
    if "+" in truth:
        return set(truth.split("+")) <= set(_found(r))
    return r["cause_found"] == truth


def _commits(recs: list[dict]) -> str:
    def short(c: str) -> str:
        head, _, rest = c.partition(" ")
        return head[:7] + ("+dirty" if "+dirty" in head else "") + (f" {rest}" if rest else "")
    return ", ".join(sorted({short(r.get("commit", "?")) for r in recs}))


def series_section(records: list[dict], variants: list[tuple[int, bool, str]],
                   visibility: dict[tuple, dict] | None = None,
                   oracle: dict[tuple, dict] | None = None) -> str:
    """Side-by-side tables (same draws): per cause and variant the share named right, with
    how many draws and which commits each cell rests on; the confusion matrix of the first
    variant; null series with a one-sided 95 % bound; time; the oracle's visible share."""
    causes = list(CAUSES)
    visibility, oracle = visibility or {}, oracle or {}
    if not records:
        return "No records yet."
    out = [f"Hidden-effect set-point series (`afmlearn.diagnose.synthetic.hidden_series`): "
           f"per draw one cause (or none, or two at once), every other parameter random (Q "
           f"150-450, free amplitude 12-40 nm, 8 set-points spread from 0.80-0.92 down to "
           f"0.30-0.45 of it, a random drive phase per row, effect strengths as in the module), "
           f"{records[0]['periods']:g} periods per set-point. Each draw is simulated once and "
           f"diagnosed in every variant: 8 pts = its 8 set-points, 4 pts = every other one "
           f"(rows 2, 4, 6, 8), 1 pt = the deepest one alone (one orbit, last 30 % of its "
           f"periods held out); `phase` = the recorded drive phase given, `no phase` = the same "
           f"file with it removed. The diagnosis never sees the labels or the file name; "
           f"thresholds: the shipped null calibration of the commit measured. Every cell says "
           f"on how many draws it rests (`k/n`); the commits are listed under each table "
           f"(records taken on a `git archive` copy of that commit, `--snapshot`)."]
    settings = sorted({(r["spp"], r["noise"]) for r in records}, reverse=True)
    vname = {v: _vname(v) for v in variants}
    short = {"none": "none", "higher_mode": "mode", "viscoelastic": "visco",
             "long_range_damping": "lr-damp", "contact_geometry": "geom",
             "adhesion_hysteresis": "hyst", "electrostatic": "elec",
             "detector_nonlinearity": "detect", "error": "error"}
    for spp, noise in settings:
        recs = [r for r in records if (r["spp"], r["noise"]) == (spp, noise)]
        by = {v: [r for r in recs if _variant(r) == v] for v in variants}
        vs = [v for v in variants if by[v]]
        rows, prov = [], []
        for c in causes[1:] + ["two effects", "none"]:
            def sel(rs: list[dict], c: str = c) -> list[dict]:
                return [r for r in rs if (r["cause"] == c if c != "two effects"
                                          else "+" in r["cause"])]
            if not any(sel(by[v]) for v in vs):
                continue
            cells, pcells = [c], [c]
            for v in vs:
                rs = sel(by[v])
                if not rs:
                    cells.append("-")
                    pcells.append("-")
                    continue
                ok = [r for r in rs if _hit(r)] if c != "none" else \
                    [r for r in rs if r["cause_found"] == "none"]
                gains = [r["gain"] for r in ok if c != "none"]
                txt = share(len(ok), len(rs))
                if gains:
                    txt += f" ({fmt(float(np.median(gains)), 2)})"
                cells.append(txt)
                pcells.append(_commits(rs))
            rows.append(cells)
            prov.append(pcells)
        out.append(f"\n### {spp} samples/period, {100 * noise:g} % noise\n\nShare named "
                   f"right, `k/n` [two-sided 95 % Clopper-Pearson interval, %] (median "
                   f"held-out gain when right); `none`: no cause named; `two effects`: both "
                   f"found among the sequential causes.\n\n"
                   + md_table(["true cause", *[vname[v] for v in vs]], rows)
                   + "\n\nCommits each cell rests on:\n\n"
                   + md_table(["true cause", *[vname[v] for v in vs]], prov))
        # confusion matrix of the main variant (first cause named)
        main = vs[0]
        labels = causes + ["error"]
        conf = np.zeros((len(causes), len(labels)), int)
        for r in by[main]:
            if r["cause"] in causes:
                f = r["cause_found"] if r["cause_found"] in labels else "error"
                conf[causes.index(r["cause"]), labels.index(f)] += 1
        crow = [[c, *[str(x) for x in conf[i]]] for i, c in enumerate(causes) if conf[i].sum()]
        if crow:
            out.append(f"\nConfusion matrix, {vname[main]} (first cause named; one-effect "
                       f"draws and nulls):\n\n"
                       + md_table(["true \\ named", *[short[c] for c in labels]], crow))
        extra_rows = []
        for v in vs:
            eff = [r for r in by[v] if r["cause"] != "none"]
            if not eff:
                continue
            right = [r for r in eff if r["cause_found"] in r["cause"].split("+")]
            extra = sum(len(set(_found(r)) - set(r["cause"].split("+")) - {"none", "error"})
                        for r in eff)
            cpu = [r["t_cpu"] for r in eff if "t_cpu" in r]
            extra_rows.append([vname[v], share(len(right), len(eff)),
                               fmt(float(np.median([r["gain"] for r in right])), 2)
                               if right else "-", str(extra),
                               f"{np.median(cpu):.1f} / {max(cpu):.1f}" if cpu else "-"])
        if extra_rows:
            out.append("\nEffect draws (one and two effects; first cause right with its "
                       "two-sided 95 % Clopper-Pearson interval, %):\n\n" + md_table(
                           ["variant", "first cause right", "median held-out gain when right",
                            "causes named that are not there",
                            "CPU time per diagnosis median / max [s]"], extra_rows))
        # null series and time
        t_rows = []
        for v in vs:
            null = [r for r in by[v] if r["cause"] == "none"]
            k = sum(r["cause_found"] != "none" for r in null)
            t = np.array([r["t_diag"] for r in by[v] if "error" not in r])
            cpu = np.array([r["t_cpu"] for r in by[v] if "t_cpu" in r])
            load = np.array([r.get("load", np.nan) for r in by[v]], float)
            t_rows.append([vname[v], f"{k}/{len(null)}" if null else "-",
                           f"{100 * upper_bound(k, len(null)):.1f} %" if null else "-",
                           f"{np.median(t):.1f}" if t.size else "-",
                           f"{t.max():.1f}" if t.size else "-",
                           f"{np.median(cpu):.1f} / {cpu.max():.1f}" if cpu.size else "-",
                           f"{np.nanmedian(load):.1f} ({np.nanmin(load):.1f}-"
                           f"{np.nanmax(load):.1f})" if np.isfinite(load).any() else "-"])
        out.append("\n" + md_table(["variant", "false cause on null series",
                                     "one-sided 95 % upper bound", "diagnosis time median [s]",
                                     "max [s]", "CPU time median / max [s]",
                                     "1-min load median (range)"], t_rows))
        # oracle: visible draws vs found (8 pts, phase, one-effect draws)
        if oracle or visibility:
            v_rows = []
            for c in causes[1:]:
                rs = [r for r in by[main] if r["cause"] == c]
                orc = [(r, oracle[_draw_key(r)]) for r in rs
                       if _draw_key(r) in oracle and "error" not in oracle[_draw_key(r)]]
                twin = [visibility[_draw_key(r)][c]["chi2_total"] for r in rs
                        if _draw_key(r) in visibility]
                if not orc and not twin:
                    continue
                vis = [r for r, o in orc if o["delta_chi2"] > o["threshold"]]
                inv = [r for r, o in orc if o["delta_chi2"] <= o["threshold"]]
                v_rows.append([
                    c, str(len(rs)),
                    f"{len(vis)}/{len(orc)}" if orc else "not computed",
                    f"{sum(_hit(r) for r in vis)}/{len(vis)}" if orc else "-",
                    f"{sum(_hit(r) for r in inv)}/{len(inv)}" if orc else "-",
                    fmt(float(np.median([o["delta_chi2"] for _, o in orc])), 2) if orc else "-",
                    _commits([o for _, o in orc]) if orc else "-",
                    fmt(float(np.median(twin)), 2) if twin else "-"])
            if v_rows:
                out.append(f"\nIs the effect visible? ({vname[main]}, one-effect draws.) "
                           f"Oracle: the true law's chi2 drop, i.e. the cause's extension "
                           f"with its shape parameter pinned at the drawn value and every "
                           f"other parameter refitted (`--oracle`; exponent, electrostatic "
                           f"radius, neck length, decay length); visible = drop above the "
                           f"cause's threshold. Twin bound: the noise-free orbit against its "
                           f"effect-free twin at the drawn parameters "
                           f"(`synthetic.effect_visibility`, harmonics 0-30 in noise units); "
                           f"the baseline refits its parameters, so this bound is far above "
                           f"any drop and only rules out a vanishing effect.\n\n"
                           + md_table(["cause", "draws", "visible (true-law drop > "
                                       "threshold)", "named / visible",
                                       "named / not visible", "median true-law drop",
                                       "oracle commits", "median twin bound"], v_rows))
        errors = [f"{r['cause']} #{r['index']} ({vname[v]}): {r['error']}" for v in vs
                  for r in by[v] if "error" in r]
        if errors:
            out.append("\nDiagnoses that raised (counted as wrong): " + "; ".join(errors))
        conf_draws = [r for r in by[main] if r["cause"] == "contact_geometry"]
        ex_rows = []
        for v in vs:
            errs, widths = [], []
            for r in by[v]:
                if r["cause"] != "contact_geometry":
                    continue
                p_true = r["case"]["effects"]["contact_geometry"]["exponent"]
                if r.get("exponent") is not None:
                    errs.append(abs(r["exponent"] - p_true))
                if r.get("exponent_interval"):
                    lo, hi = r["exponent_interval"]
                    widths.append(hi - lo)
            if errs:
                ex_rows.append([vname[v], fmt(float(np.median(errs)), 2),
                                f"{sum(e <= 0.1 for e in errs)}/{len(errs)}",
                                fmt(float(np.median(widths)), 2) if widths else "-"])
        if conf_draws and ex_rows:
            out.append("\nContact exponent on the `contact_geometry` draws (true p 1.9-2.4):"
                       "\n\n" + md_table(["variant", "median abs(p - p_true)", "within 0.1",
                                           "median 95 % interval width"], ex_rows))
    return "\n".join(out)


#: causes whose extension has a nonlinear shape parameter the oracle can pin at the truth
ORACLE_CAUSES = ("contact_geometry", "electrostatic", "adhesion_hysteresis",
                 "long_range_damping")


def _truth_value(case: dict, cause: str) -> tuple[float, bool]:
    """The drawn value of the cause's nonlinear parameter (and whether it is a length)."""
    e = case["effects"][cause]
    if cause == "contact_geometry":
        return e["exponent"], False
    if cause == "electrostatic":
        return case["tip_radius_m"], True
    if cause == "long_range_damping":
        return e["decay_length_m"], True
    # JKR neck length of the simulator's hysteretic law: 3/4 c s, c = sqrt(2 pi w / E*),
    # s = (c R / 4)^(1/3)
    c = math.sqrt(2 * math.pi * e["work_of_adhesion_j_per_m2"] / case["reduced_modulus_pa"])
    return 0.75 * c * (c * case["tip_radius_m"] / 4) ** (1 / 3), True


def _pinned(cause: str, value: float, is_length: bool):
    """The cause's hypothesis with its nonlinear parameter held at ``value`` (SI)."""
    from afmlearn.diagnose import hypotheses as hyp
    from afmlearn.diagnose.hypotheses.base import AbstractHypothesis, Parameter

    inner = {h.cause: h for h in (hyp.ContactGeometry(), hyp.Electrostatic(),
                                  hyp.AdhesionHysteresis(), hyp.LongRangeDamping())}[cause]

    @final
    class Pinned(AbstractHypothesis):
        """``inner`` with its one nonlinear parameter fixed (linear terms still fitted)."""

        def __init__(self) -> None:
            self.cause = inner.cause
            self.a0_factor, self.a0_grid = inner.a0_factor, inner.a0_grid

        def parameters(self, ctx):
            v = value / ctx.length_m if is_length else value
            p = inner.parameters(ctx)[0]
            return [Parameter(p.name, v * (1 - 1e-4), v * (1 + 1e-4), (v,), log=True,
                              nested=p.nested)]

        def extend(self, spec, values):
            return inner.extend(spec, values)

        def nested_values(self, params):
            return [params[0].grid[0]]

    return Pinned()


def _oracle_job(job: dict) -> dict:
    """The true law's chi2 drop on one draw: the cause's extension with its nonlinear
    parameter pinned at the drawn value, everything else refitted (investigation: it reads
    the truth from the record, which the diagnosis under test never sees)."""
    path, case = _series_file(job, Path(job["files"]))
    if _design(job) == "two":                           # one experiment of both files
        from afmlearn.diagnose.observation import read_experiment
        from afmlearn.diagnose.synthetic import series_files
        exp = read_experiment(series_files(path))       # no labels
    else:
        exp = Experiment.read(path)
    t0 = time.perf_counter()
    h = _pinned(job["cause"], *_truth_value(case, job["cause"]))
    try:
        d = Diagnoser(hypotheses=[h], max_causes=1, screen_chi2=0.0).fit(exp)
        c = d.candidates_[0]
        out = {"delta_chi2": float(c.delta_chi2), "threshold": float(c.threshold),
               "gain": float(c.gain)}
    except Exception as err:  # noqa: BLE001 -- an oracle failure is reported, not fatal
        out = {"error": f"{type(err).__name__}: {err}"}
    return {**job, **out, "t": time.perf_counter() - t0, "commit": code_version()}


def oracle_pass(records: list[dict], path: Path) -> dict[tuple, dict]:
    """:func:`_oracle_job` on every one-effect 8-point draw of :data:`ORACLE_CAUSES` in
    ``records`` (each design: one amplitude, two, twin; resumable, one JSON line per draw in
    ``path``)."""
    jobs = [{**{k: r[k] for k in ("set_id", "spp", "noise", "cause", "index", "seed",
                                  "periods", "files")}, "design": _design(r)} for r in records
            if r["cause"] in ORACLE_CAUSES and _variant(r)[:2] == (8, True)]
    jobs = list({_draw_key(j): j for j in jobs}.values())
    recs = run_jobs(jobs, path, 1, job=_oracle_job, key=_draw_key, desc="oracle")
    return {_draw_key(r): r for r in recs}


def _draw_key(r: dict) -> tuple:
    """One simulated draw (the one-amplitude key of old records; other designs appended)."""
    key = (r["set_id"], r["spp"], r["noise"], r["cause"], r["index"], r["seed"], r["periods"])
    return key if _design(r) == "one" else (*key, _design(r))


def visibility_pass(records: list[dict], path: Path, n_harmonics: int = 30) -> dict[tuple, dict]:
    """The oracle (:func:`afmlearn.diagnose.synthetic.effect_visibility`) of every effect draw
    in ``records`` (resumable: one JSON line per draw in ``path``)."""
    from afmlearn.diagnose.synthetic import SeriesCase, effect_visibility

    out: dict[tuple, dict] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                out[tuple(r["key"])] = r["visibility"]
    todo = {}
    for r in records:
        if r["cause"] != "none" and r.get("case") and _draw_key(r) not in out:
            todo[_draw_key(r)] = r
    with open(path, "a") as f:
        for k, r in tqdm(todo.items(), desc="visibility", disable=None):
            vis = effect_visibility(SeriesCase.from_dict(r["case"]), samples_per_period=r["spp"],
                                    n_periods=r["periods"], noise_level=r["noise"],
                                    n_harmonics=n_harmonics)
            f.write(json.dumps({"key": list(k), "visibility": vis}) + "\n")
            f.flush()
            out[k] = vis
    return out


def series_calibrate(args: argparse.Namespace, settings: list[tuple[int, float]],
                     rec_dir: Path) -> int:
    """Null calibration on set-point series: ``--null`` null series per setting (8 set-points,
    drive phase recorded; seeds disjoint from the evaluation draws: ``set_id`` 5), diagnosed
    one by one (resumable: ``series_null.jsonl``); the thresholds (:func:`calibrate`) go to
    the ``"series"`` section of ``null_calibration.json``, the single-record ones are kept.
    ``--design two``: null experiments of 2 free amplitudes x 4 set-points (``set_id`` 6,
    ``series_null_2amp.jsonl``) into the ``"series_amplitudes"`` section, which the
    diagnosis selects for an experiment with more than one drive group. ``--no-phase`` (one
    amplitude): null series with the drive phase removed from the files (``set_id`` 7,
    ``series_null_nophase.jsonl``) into the ``"series_nophase"`` section, which the diagnosis
    selects for a series without recorded drive phases."""
    two = args.design == "two"
    nophase = args.no_phase and not two
    set_id, section = ((6, "series_amplitudes") if two else (7, "series_nophase") if nophase
                       else (5, "series"))
    what = ("null experiments of 2 free amplitudes x 4 set-points" if two
            else "null 8-set-point series without the recorded drive phase" if nophase
            else "null 8-set-point series")
    null_file = rec_dir / ("series_null_2amp.jsonl" if two else
                           "series_null_nophase.jsonl" if nophase else "series_null.jsonl")
    jobs = [{"set_id": set_id, "spp": spp, "noise": noise, "cause": "none", "index": i,
             "seed": args.seed, "periods": args.periods, "n_points": 8, "phase": not nophase,
             "design": args.design, "files": str(rec_dir / "series_null_files")}
            for i in range(args.null) for spp, noise in settings]
    if args.report_only:
        have = {_series_key(r): r for r in _latest(null_file, args.since)}
        recs = [have[_series_key(j)] for j in jobs if _series_key(j) in have]
    else:
        recs = run_series_jobs(jobs, null_file, args.workers, since=args.since)
    if args.keep_thresholds and not two and not nophase:
        return series_null_check(recs, rec_dir, args)
    ok = [r for r in recs if r.get("candidates")]
    if not ok:
        print("no null series diagnosed yet")
        return 1
    calib = calibrate(ok, args.family_rate)
    n_false = sum(any(c["delta_chi2"] > calib.thresholds[c["cause"]] for c in r["candidates"])
                  for r in ok)
    n_named = sum(r["cause_found"] != "none" for r in ok)
    idx = sorted(r["index"] for r in ok)
    phase_note = ("(drive phase not recorded: removed from the files)" if nophase
                  else "(drive phase recorded)")
    src = (calib.source.replace("null traces", f"{what} {phase_note}")
           + f"; {args.periods:g} periods per set-point; seeds: set_id {set_id}, seed {args.seed}, "
           f"draws {idx[0]}-{idx[-1]}; commits {_commits(ok)}; {len(recs) - len(ok)} raised; "
           f"{n_false}/{len(ok)} null series with a chi2 drop above these thresholds "
           f"(in-sample), {n_named}/{len(ok)} with a cause named (drop and held-out gain); "
           f"one-sided 95 % upper bound on the family-wise false-cause rate from these "
           f"(in-sample) {100 * upper_bound(n_named, len(ok)):.1f} %")
    d = json.loads(CALIBRATION.read_text())
    old = d.get(section, {})
    commits = sorted({r.get("commit", "?") for r in ok})
    prev = old.get("thresholds")
    if old.get("provenance", {}).get("commits") == commits:    # a re-write of the same run
        prev = old["provenance"].get("previous_thresholds")
    d[section] = {"thresholds": calib.thresholds, "min_gain": calib.min_gain, "source": src,
                   "provenance": {
                       "commits": commits,
                       "n_null_series": len(ok), "set_id": set_id, "seed": args.seed,
                       "draws": [idx[0], idx[-1]],
                       "samples_per_period_noise": sorted({(r["spp"], r["noise"])
                                                           for r in ok}),
                       "periods_per_setpoint": args.periods, "n_points": 8,
                       "free_amplitudes": 2 if two else 1,
                       "drive_phase": not nophase, "family_rate": args.family_rate,
                       "previous_thresholds": prev}}
    if not args.no_doc:
        tmp = CALIBRATION.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(d, indent=1) + "\n")
        os.replace(tmp, CALIBRATION)
    print(f"{section} thresholds:", calib.thresholds)
    print(src)
    return 0


def null_table(nulls: list[dict]) -> str:
    """False-cause rate on null series per setting and variant (per commit, then pooled with
    each draw once), with the one-sided 95 % Clopper--Pearson bound, and how close the
    first-step drops came to the thresholds."""
    groups: dict[tuple, list[dict]] = {}
    for r in nulls:
        # the calibration's own nulls (set_id 5) are in-sample for the thresholds they set:
        # listed apart, never pooled with the evaluation's
        groups.setdefault((r["spp"], r["noise"], *_variant(r),
                           r.get("set_id") if r.get("set_id") in (5, 6) else 0), []).append(r)
    rows = []
    split: list[tuple[tuple, list[dict]]] = []
    for g, rs in sorted(groups.items(), reverse=True):
        by_commit: dict[str, list[dict]] = {}
        for r in rs:
            by_commit.setdefault(_commits([r]), []).append(r)
        split += [(g, v) for _, v in sorted(by_commit.items())]
        if len(by_commit) > 1:
            # pooled: each draw once (the record listed last, i.e. the later re-run)
            split.append((g, list({_series_key(r): r for r in rs}.values())))
    for (spp, noise, n_pts, phase, design, cal), rs in split:
        ok = [r for r in rs if r.get("candidates")]
        k = sum(r["cause_found"] != "none" for r in rs)       # a raise is not a false cause
        above = sum(any(c["delta_chi2"] > c["threshold"] for c in r["candidates"]) for r in ok)
        ratio = [max(c["delta_chi2"] / c["threshold"] for c in r["candidates"]) for r in ok]
        rows.append([f"{spp} spp, {100 * noise:g} %", _vname((n_pts, phase, design))
                     + {5: " (calibration nulls: in-sample)",
                        6: " (`--design two` calibration nulls)"}.get(cal, ""),
                     str(len(rs)), f"{k}/{len(rs)}",
                     f"{100 * upper_bound(k, len(rs)):.1f} %", f"{above}/{len(ok)}",
                     fmt(float(np.median(ratio)), 2) if ratio else "-",
                     fmt(float(np.max(ratio)), 3) if ratio else "-",
                     str(len(rs) - len(ok)), _commits(rs)])
    return md_table(["setting", "variant", "null series", "cause named (false)",
                     "one-sided 95 % upper bound", "a first-step drop above its threshold",
                     "largest drop / threshold: median", "max", "raised", "commits"], rows)


def _latest(path: Path, since: str = "", key=None) -> list[dict]:
    """The last record of each key in a JSON-lines file (taken on ``since`` or later)."""
    accept = _since(since) if since else (lambda r: True)
    last: dict[tuple, dict] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if accept(r):
                    last[(key or _series_key)(r)] = r
    return list(last.values())


def harness_records(path: Path) -> list[dict]:
    """Records of R's harness (``outputs/R/harness.py``: the same draws, 8 points with the
    drive phase, 200 spp / 1 %, 30 periods, seed 2026) in this benchmark's format; the commit
    comes from the sibling ``<stem>.commit`` file."""
    if not path.exists():
        return []
    stamp = path.with_suffix(".commit")
    commit = stamp.read_text().strip() if stamp.exists() else "?"
    out = []
    for line in path.read_text().splitlines():
        if not line.strip():
            continue
        h = json.loads(line)
        f = path.parent / "draws" / h.get("file", "")
        if h.get("file") and f.exists():
            y = read_trace(f)
            if np.any(np.abs(y.deflection_m).max(axis=1) > 1.5 * y.free_amplitude_m):
                continue        # a diverged row (the generator before f336ff8): not data
        r = {"set_id": 3, "spp": 200, "noise": 0.01, "cause": h["cause"], "index": h["index"],
             "seed": 2026, "periods": 30.0, "n_points": 8, "phase": True,
             "case": {"effects": h.get("effects") or {}}, "commit": commit + " (R)",
             "t_diag": h.get("t", math.nan), "exponent": None, "exponent_interval": None}
        if "error" in h:
            r.update(error=h["error"], cause_found="error", causes_found=[], gain=0.0,
                     candidates=[])
        else:
            r.update(cause_found=h["found"], gain=h["gain"],
                     causes_found=[{"cause": c, "gain": math.nan} for c in h["causes"]],
                     candidates=[{"cause": c[0], "delta_chi2": c[2], "threshold": c[3],
                                  "gain": c[4]} for c in h["cands"]])
        out.append(r)
    return out


def series_null_check(recs: list[dict], rec_dir: Path, args: argparse.Namespace) -> int:
    """``--keep-thresholds``: pool the calibration nulls with the evaluation's null draws
    (``series.jsonl``, disjoint seeds), report the false-cause rate with the shipped
    thresholds and write it into the ``"series"`` source of ``null_calibration.json``."""
    pool = list(recs) + [r for r in _latest(rec_dir / "series.jsonl", args.since)
                         if r["cause"] == "none"]
    for extra in filter(None, args.harness.split(",")):
        pool += [r for r in harness_records(Path(extra)) if r["cause"] == "none"]
    table = null_table(pool)
    print(table)
    pool = list({_series_key(r): r for r in pool}.values())    # each draw once, latest
    main = [r for r in pool if _variant(r) == (8, True, "one") and r["spp"] == 200]
    if not main:
        return 1
    k = sum(r["cause_found"] != "none" for r in main)
    d = json.loads(CALIBRATION.read_text())
    sec = d["series"]
    base = sec["source"].split("; re-checked")[0]
    sec["source"] = (base + f"; re-checked (bench_diagnose.py --series --calibrate "
                     f"--keep-thresholds, thresholds unchanged) on {len(main)} null 8-set-point "
                     f"series at 200 spp / 1 %, drive phase recorded, commits "
                     f"{_commits(main)}: {k} named a cause, one-sided 95 % upper bound on the "
                     f"family-wise false-cause rate {100 * upper_bound(k, len(main)):.1f} %")
    dropped = sum(r["cause"] == "none" for n in ("series_null_invalid.jsonl",
                                                   "series_invalid.jsonl")
                  for r in _latest(rec_dir / n))
    if dropped:
        sec["source"] += (f" ({dropped} null series with a diverged simulated row, "
                          f"|deflection| > 1.5 free amplitudes, left out)")
    if not args.no_doc:
        tmp = CALIBRATION.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(d, indent=1) + "\n")
        os.replace(tmp, CALIBRATION)
    print(sec["source"])
    return 0


def _parse_variant(text: str) -> tuple[int, bool, str]:
    """``8:phase`` (8 set-points at one free amplitude), ``4:none``, ``2x4:phase`` (two free
    amplitudes x 4 set-points), ``twin:phase`` (that draw at its first amplitude, 8 rows)."""
    n, _, ph = text.partition(":")
    if ph not in ("phase", "none"):
        raise ValueError(f"--variants: each is n_points:phase|none, got {text!r}")
    if n == "2x4":
        return 8, ph == "phase", "two"
    if n == "twin":
        return 8, ph == "phase", "twin"
    if int(n) not in SUBSETS:
        raise ValueError(f"--variants: n_points must be one of {sorted(SUBSETS)}, 2x4 or "
                         f"twin, got {text!r}")
    return int(n), ph == "phase", "one"


def _vname(v: tuple[int, bool, str]) -> str:
    ph = "phase" if v[1] else "no phase"
    if v[2] == "two":
        return f"2 amps x 4 pts, {ph}"
    if v[2] == "twin":
        return f"1 amp x 8 pts (twin of 2 amps), {ph}"
    return f"{v[0]} pt{'s' if v[0] > 1 else ''}, {ph}"


def series_main(args: argparse.Namespace, settings: list[tuple[int, float]],
                info: dict[str, str]) -> int:
    variants = [_parse_variant(v) for v in args.variants.split(",")]
    rec_dir = Path(args.records)
    if args.snapshot and not os.environ.get("BENCH_DIAGNOSE_CODE"):
        # run on a clean copy of one commit (the shared tree may hold others' edits)
        snap = git_snapshot(args.snapshot, rec_dir / "code")
        argv = [a for a in sys.argv if not a.startswith("--snapshot")]
        if "--snapshot" in sys.argv:
            i = sys.argv.index("--snapshot")
            argv = sys.argv[:i] + sys.argv[i + 2:]
        env = {**os.environ, "BENCH_DIAGNOSE_CODE": str(snap)}
        os.execve(sys.executable, [sys.executable, *argv], env)
    if args.calibrate:
        return series_calibrate(args, settings, rec_dir)
    jobs = series_jobs(settings, args.per_cause, args.pairs, args.periods, args.seed,
                       rec_dir / "series_files", variants,
                       causes=args.causes.split(",") if args.causes else None,
                       first=args.first)
    if args.report_only:            # the section from the records so far (a run in progress)
        path = rec_dir / "series.jsonl"
        have = {}
        if path.exists():
            for line in path.read_text().splitlines():
                if line.strip():
                    r = json.loads(line)
                    if not args.since or _since(args.since)(r):
                        have[_series_key(r)] = r
        recs = [have[_series_key(j)] for j in jobs if _series_key(j) in have]
        # a harness record replaces this benchmark's record of the same draw when it was
        # taken on a later commit
        at = {_series_key(r): i for i, r in enumerate(recs)}
        for extra in filter(None, args.harness.split(",")):
            for r in harness_records(Path(extra)):
                k = _series_key(r)
                if k not in at:
                    at[k] = len(recs)
                    recs.append(r)
                elif _newer(r["commit"], recs[at[k]].get("commit", "")):
                    recs[at[k]] = r
        # records of another records folder (this benchmark's format, e.g. another
        # engineer's variant on the same draws): added where this folder has no record of
        # the same draw and variant (this folder's record wins)
        want = {_series_key(j) for j in jobs}
        for extra in _merge_paths(args.merge):
            for r in _latest(extra, args.since):
                k = _series_key(r)
                if k in want and k not in at:
                    at[k] = len(recs)
                    recs.append(r)
    else:
        recs = run_series_jobs(jobs, rec_dir / "series.jsonl", args.workers, since=args.since)
    vis_path = rec_dir / "visibility.jsonl"
    vis = visibility_pass(recs, vis_path) if args.visibility else (
        visibility_pass([], vis_path) if vis_path.exists() else {})
    orc_path = rec_dir / "oracle.jsonl"
    orc = oracle_pass(recs, orc_path) if args.oracle else (
        {_draw_key(r): r for r in _latest(orc_path, key=_draw_key)})
    body = series_section(recs, variants, vis, orc)
    nulls = (_latest(rec_dir / "series_null.jsonl", args.since)
             + _latest(rec_dir / "series_null_2amp.jsonl", args.since)
             + [r for r in _latest(rec_dir / "series.jsonl", args.since) if r["cause"] == "none"])
    for extra in filter(None, args.harness.split(",")):
        nulls += [r for r in harness_records(Path(extra)) if r["cause"] == "none"]
    own = {_series_key(r) for r in nulls}
    for extra in _merge_paths(args.merge):
        nulls += [r for r in _latest(extra, args.since)
                  if r["cause"] == "none" and _series_key(r) not in own]
    if nulls:
        body += ("\n\n### Null series: false-cause rate with the shipped thresholds\n\n"
                 "The evaluation's null draws (out of sample: seeds disjoint from the "
                 "calibration's) and, listed apart, the calibration's own null series "
                 "(`--calibrate`, in-sample for the thresholds they set: a 99.29 % quantile "
                 "of ~30 values is about their largest); a false cause = a cause named (drop "
                 "above its threshold and held-out gain above 0.05). The bound is the "
                 "one-sided 95 % Clopper-Pearson bound of the family-wise false-cause rate."
                 "\n\n" + null_table(nulls))
    if args.note:
        body += "\n\n" + args.note
    if args.note_file:
        body += "\n\n" + Path(args.note_file).read_text().strip()
    write_section(args.section, series_title(variants), body, info, write=not args.no_doc)
    return 0


def _merge_paths(text: str) -> list[Path]:
    """``--merge``: comma-separated ``series.jsonl`` files (or their records folders)."""
    paths = [Path(p) for p in filter(None, text.split(","))]
    paths = [p / "series.jsonl" if p.is_dir() else p for p in paths]
    for p in paths:
        if not p.exists():
            raise ValueError(f"--merge: no records file {p}")
    return paths


def series_title(variants: list[tuple[int, bool, str]]) -> str:
    """The section title: the one-amplitude comparison (8 / 4 / 1 set-points, with and
    without the drive phase) or, when every variant is of the two-amplitude draw, that."""
    if variants and all(v[2] in ("two", "twin") for v in variants):
        return ("Diagnosis on two-free-amplitude series: 2 amplitudes x 4 set-points vs the "
                "one-amplitude twin (`bench_diagnose.py --series`)")
    return ("Diagnosis on set-point series: one orbit vs 4 vs 8 set-points, with and without "
            "the drive phase (`bench_diagnose.py --series`)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-cause", type=int, default=10)
    ap.add_argument("--null", type=int, default=30, help="null traces per setting (calibration)")
    ap.add_argument("--settings", default="1000:0.005,200:0.01",
                    help="comma-separated samples_per_period:noise pairs")
    ap.add_argument("--periods", type=float, default=300.0)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--family-rate", type=float, default=0.05,
                    help="family-wise false-cause rate of the null calibration")
    ap.add_argument("--calibrate", action="store_true",
                    help="recompute the null thresholds first and write them")
    ap.add_argument("--records", default=str(ROOT / "outputs" / "bench_diagnose"))
    ap.add_argument("--quick", action="store_true", help="1 trace per cause, 200 spp, no doc")
    ap.add_argument("--series", action="store_true",
                    help="set-point series: 1 vs 4 vs 8 set-points, with/without drive phase")
    ap.add_argument("--pairs", type=int, default=2,
                    help="series: draws per pair of effects (two effects at once)")
    ap.add_argument("--note", default="", help="series: a closing paragraph for the section")
    ap.add_argument("--note-file", default="",
                    help="series: a markdown file appended to the section (not echoed in "
                         "the command line)")
    ap.add_argument("--report-only", action="store_true",
                    help="series: write the section from the records so far, run nothing")
    ap.add_argument("--causes", default="",
                    help="series: comma-separated single causes to draw (default: all)")
    ap.add_argument("--variants", default="1:phase,4:phase,8:phase,1:none,4:none,8:none",
                    help="series: comma-separated n_points:phase|none")
    ap.add_argument("--design", choices=("one", "two"), default="one",
                    help="series --calibrate: one free amplitude (8 set-points, section "
                         "'series') or two (2 x 4, section 'series_amplitudes')")
    ap.add_argument("--no-phase", action="store_true",
                    help="series --calibrate: null series with the drive phase removed "
                         "(section 'series_nophase', set_id 7)")
    ap.add_argument("--keep-thresholds", action="store_true",
                    help="series --calibrate: keep the shipped thresholds, report and record "
                         "the false-cause rate on the null series (with the evaluation's)")
    ap.add_argument("--harness", default="",
                    help="series --report-only: comma-separated JSON-lines files of R's harness "
                         "(same draws) merged where this benchmark has no record")
    ap.add_argument("--merge", default="",
                    help="series --report-only: comma-separated series.jsonl files (or records "
                         "folders) of this benchmark merged where --records has no record of "
                         "the same draw and variant")
    ap.add_argument("--first", type=int, default=0,
                    help="series: first draw index of the single causes (split a run)")
    ap.add_argument("--oracle", action="store_true",
                    help="series: the true law's drop (shape parameter pinned at the truth) "
                         "on every 8-point draw of " + ", ".join(ORACLE_CAUSES))
    ap.add_argument("--visibility", action="store_true",
                    help="series: compute the oracle visibility of every effect draw first")
    ap.add_argument("--since", default="",
                    help="series: stored records count as done only if taken on this commit "
                         "or a later one (re-run what a change affects)")
    ap.add_argument("--snapshot", default="",
                    help="series: run on a git-archive copy of this commit (e.g. HEAD) "
                         "instead of the working tree; records name the commit")
    ap.add_argument("--section", default="diagnose_series",
                    help="series: the docs/benchmarks.md section written (two runs from "
                         "different record folders keep apart, e.g. diagnose_series_2amp)")
    add_doc_flag(ap)
    args = ap.parse_args(argv)
    info = machine_info()
    settings = [(int(a), float(b)) for a, b in (s.split(":") for s in args.settings.split(","))]
    if args.quick:
        settings, args.per_cause, args.null, args.no_doc = [(200, 0.01)], 1, 4, True
    if args.series:
        if args.periods == 300.0:
            args.periods = 40.0
        return series_main(args, settings, info)
    rec_dir = Path(args.records)
    n_null = 0
    calib = NullCalibration.default()
    if args.calibrate:
        jobs = [{"set_id": 1, "spp": spp, "noise": noise, "cause": "none", "index": i,
                 "seed": args.seed, "periods": args.periods}
                for spp, noise in settings for i in range(args.null)]
        null = run_jobs(jobs, rec_dir / "null.jsonl", args.workers)
        calib = calibrate(null, args.family_rate)
        n_null = len(null)
        if not args.no_doc:
            tmp = CALIBRATION.with_suffix(".json.tmp")
            tmp.write_text(json.dumps({"thresholds": calib.thresholds,
                                       "min_gain": calib.min_gain,
                                       "source": calib.source}, indent=1) + "\n")
            os.replace(tmp, CALIBRATION)
        print("thresholds:", calib.thresholds)
    results = {}
    for spp, noise in settings:
        jobs = [{"set_id": 2, "spp": spp, "noise": noise, "cause": c, "index": i,
                 "seed": args.seed, "periods": args.periods}
                for i in range(args.per_cause) for c in CAUSES]
        recs = run_jobs(jobs, rec_dir / "eval.jsonl", args.workers)
        results[(spp, noise)] = evaluate(recs, calib)
    body = section(results, calib, n_null or null_count(calib.source))
    write_section("diagnose", "Diagnosis: hidden-effect confusion matrix (`bench_diagnose.py`)",
                  body, info, write=not args.no_doc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
