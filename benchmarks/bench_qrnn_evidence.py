"""Diagnosis with and without the QRNN's evidence, side by side on the same draws (issue 15).

The ``higher_mode`` hypothesis with ``qrnn=True`` adds prior log-odds
``w * max(0, LLR)`` (``afmlearn/diagnose/hypotheses/higher_mode.py``) to its decision: the
diagnoser lowers the cause's null threshold on the chi-square drop by twice it. This benchmark
takes the hidden-effect **series** draws that ``benchmarks/bench_diagnose.py --series`` diagnosed
(their records, one JSON line per draw and variant, and their trace files), scores every
set-point with the shipped QRNN (`afmlearn.qrnn.coupling_probability`, no labels), and
re-takes the first-step decision (`afmlearn.diagnose.diagnoser.name_cause`, with the recorded
evidence, held-out gains and thresholds of every cause) once without and once with the QRNN's
log-odds. Same draws, same fits: only the prior differs. A draw whose decision could change
only through a held-out gain that the diagnosis did not compute (it computes gains only as far
as its own decision needs) is counted as "undetermined" (none occurred when the column is 0).

    python benchmarks/bench_qrnn_evidence.py [--records outputs/bench_diagnose/series.jsonl]
        [--weight 0.9] [--no-doc]

Section ``qrnn_evidence`` of ``docs/benchmarks.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _common import ROOT, add_doc_flag, machine_info, md_table, write_section  # noqa: E402

from afmlearn.diagnose.diagnoser import name_cause  # noqa: E402
from afmlearn.diagnose.hypotheses.higher_mode import QRNN_WEIGHT, qrnn_log_odds  # noqa: E402
from afmlearn.io import read_trace  # noqa: E402
from afmlearn.qrnn.evidence import CouplingEvidence, coupling_probability  # noqa: E402

#: the set-points of each variant, as bench_diagnose.SUBSETS
SUBSETS = {8: list(range(8)), 4: [1, 3, 5, 7], 1: [7]}
MIN_GAIN = 0.05


def _subset(ev: CouplingEvidence, rows: list[int]) -> CouplingEvidence:
    arrays = {f.name: getattr(ev, f.name)[rows] for f in dataclasses.fields(ev)
              if isinstance(getattr(ev, f.name), np.ndarray)}
    return dataclasses.replace(ev, **arrays)


def _decide(cands: list[dict], log_odds: float) -> tuple[str, bool]:
    """First-step cause with ``log_odds`` added for higher_mode; and whether an uncomputed
    gain could have changed it."""
    d = [float(c["delta_chi2"]) for c in cands]
    g = [float(c["gain"]) for c in cands]
    t = [float(c["threshold"]) - (2.0 * log_odds if c["cause"] == "higher_mode" else 0.0)
         for c in cands]
    # only the lowered higher_mode threshold can make a candidate without a computed gain
    # matter that the recorded decision did not need
    unknown = log_odds > 0 and any(
        c["cause"] == "higher_mode" and math.isnan(gi) and di > ti
        and di <= float(c["threshold"]) for c, di, gi, ti in zip(cands, d, g, t, strict=True))
    g_known = [(-math.inf if math.isnan(gi) else gi) for gi in g]
    idx, _ = name_cause(d, g_known, t, MIN_GAIN)
    return ("none" if idx is None else cands[idx]["cause"]), unknown


def _truth_share(path: Path) -> list[float]:
    """Coupling share (modes >= 2) of every set-point, from the labels (benchmark only)."""
    from simulator.labels import coupling_strength

    lab = read_trace(path, labels=True).labels
    modal = None if lab is None or lab.modal_m is None else np.asarray(lab.modal_m)
    if modal is None or modal.shape[0] < 2:
        return [0.0] * 8
    return [float(coupling_strength(modal[:, i])) for i in range(modal.shape[1])]


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", type=Path, nargs="+",
                    default=[ROOT / "outputs" / "bench_diagnose" / n for n in
                             ("series_before_D2.jsonl", "series_null.jsonl")],
                    help="bench_diagnose --series record files (JSON lines; missing: skipped)")
    ap.add_argument("--weight", type=float, default=QRNN_WEIGHT)
    add_doc_flag(ap)
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    records = [json.loads(line) for f in args.records if f.is_file()
               for line in f.read_text().splitlines() if line]
    records = [r for r in records if r.get("candidates") and "error" not in r]
    evidence: dict[str, CouplingEvidence] = {}
    shares: dict[str, list[float]] = {}
    rows = defaultdict(lambda: {"n": 0, "without": 0, "with": 0, "changed": 0,
                                "undetermined": 0, "lo": [], "p": []})
    mismatch = 0
    for r in records:
        key = json.dumps([r["set_id"], r["spp"], r["noise"], r["cause"], r["index"],
                          r["seed"], r["periods"]])
        import hashlib

        path = Path(r["files"]) / (hashlib.sha1(key.encode()).hexdigest()[:16] + ".h5")
        if not path.is_file():
            continue
        if str(path) not in evidence:
            evidence[str(path)] = coupling_probability(read_trace(path))   # no labels
            shares[str(path)] = _truth_share(path)
        ev = _subset(evidence[str(path)], SUBSETS[r["n_points"]])
        lo = qrnn_log_odds(ev, weight=args.weight)
        without, _ = _decide(r["candidates"], 0.0)
        with_, unknown = _decide(r["candidates"], lo)
        mismatch += without != r["cause_found"]
        truth = r["cause"].split("+")
        for variant in (f"{r['n_points']} set-point(s){'' if r['phase'] else ', no phase'}",
                        "all variants"):
            row = rows[(r["cause"], variant)]
            row["n"] += 1
            row["without"] += without in truth
            row["with"] += with_ in truth
            row["changed"] += with_ != without
            row["undetermined"] += unknown
            row["lo"].append(lo)
            row["p"].append(float(np.max(ev.probability)))
    table = md_table(
        ["hidden cause", "variant", "draws", "first cause correct: without / with QRNN",
         "decisions changed", "undetermined", "QRNN log-odds added (max)",
         "largest QRNN probability (median / max)"],
        [[c, v, x["n"], f"{x['without']} / {x['with']}", x["changed"], x["undetermined"],
          f"{max(x['lo']):.2f}", f"{np.median(x['p']):.3f} / {max(x['p']):.3f}"]
         for (c, v), x in sorted(rows.items()) if v == "all variants" or c == "higher_mode"])
    all_shares = [s for v in shares.values() for s in v]
    nrmse = np.concatenate([e.forecast_nrmse for e in evidence.values()])
    prob = np.concatenate([e.probability for e in evidence.values()])
    out = nrmse > 0.1
    p_out = f"{prob[out].max():.2f}" if out.any() else "-"
    body = f"""
Command: `python benchmarks/bench_qrnn_evidence.py --records {' '.join(
    str(f.relative_to(ROOT)) if f.is_relative_to(ROOT) else str(f) for f in args.records)}`
(weight w = {args.weight:g}). Draws: the {len(evidence)} hidden-effect series (8 set-points,
200 samples per period, 1 % noise, 30 periods each; `afmlearn.diagnose.synthetic.hidden_series`)
of `bench_diagnose.py --series` (effect draws of the previous code, and the null draws of the
series null calibration running now) and their {len(records)} diagnosed variants (1, 4 or 8
set-points, drive phase recorded or not), as recorded in those files. The decision is re-taken
from the recorded per-cause evidence, gains and thresholds (sanity: {mismatch} of
{len(records)} re-taken decisions without the QRNN differ from the recorded ones). "With
QRNN": the higher_mode threshold lowered by 2 x the log-odds of the network's calibrated
probability (largest over the variant's
set-points, positive evidence only, weight {args.weight:g}).

{table}

Set-points the network forecasts with NRMSE > 0.1 (outside its range: no evidence):
{int(out.sum())} of {out.size}; their probabilities reach {p_out} (the
largest in range: {prob[~out].max():.3f}) -- without that gate, a draw with such a set-point
above the base rate would have given higher_mode a prior.

The coupling share of modes >= 2 (labels, read here only) over all {len(all_shares)} set-points
of these draws: max {max(all_shares):.2e} (the QRNN's "coupled" line: 3e-3): the diagnosis
generator's second modes (ratio 5.85-6.3, small modal gain) stay far below what the network
was trained to flag, its probabilities stay below the base rate of its calibration set, and the
one-sided rule adds nothing: the decisions are the same with and without it, by design (w = 0
where the network is outside its range). Where it is in range (a second mode carrying > 5.5 %
of the RMS motion) its evidence is worth up to {2 * 4.0:g} on the chi-square scale (cap 4 in
log-odds), against a higher_mode null threshold of ~15.
"""
    info = machine_info()
    return write_section("qrnn_evidence", "Diagnosis with and without the QRNN's evidence",
                         body, info, write=not args.no_doc)


if __name__ == "__main__":
    main()
