"""Lock-in curve benchmark: force error against the peer inversion, cause accuracy per cause.

Protocol (issue 14 part 3):

1. For each cause (``none`` and the six curve causes) ``--per-cause`` synthetic approach--retract
   curves are simulated in the time domain (``simulator.scenarios.LockInCurve``: RK4 of the
   single-mode lever, lock-in demodulation with a 4th-order 1 kHz filter) with an
   Asylum-like lever (k 2.7 N/m, f0 72.35 kHz, Q 187); sample, amplitude, ramp and effect size
   are drawn per curve; 1 % amplitude and 0.5 deg phase noise.
2. The analysis sees only the curve (amplitude, phase, piezo position, segment, calibration):
   no labels, file names or seeds (hidden-effect discipline); the case order is shuffled.
3. Force error: NRMSE (``design.md`` section 4) of the conservative force at the lower turning
   points of the approach where the amplitude is reduced (interaction zone), afmlearn's
   fitted law against the truth, and the peer inversions (Katan/Payam Sader--Jarvis and
   Hoelscher, ``benchmarks/peer_inversion.py``), which are given the true surface position
   and drive (an advantage: afmlearn fits both).

Records go to a JSON-lines file (resumable). Run: ``python benchmarks/bench_curves.py``.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402
from _common import ROOT, add_doc_flag, fmt, machine_info, md_table, write_section  # noqa: E402
from scipy import signal  # noqa: E402

from afmlearn.curves import (  # noqa: E402
    EXTENSIONS,
    Curve,
    CurveDiagnoser,
    CurveFitter,
    CurveLaw,
)
from afmlearn.metrics import nrmse  # noqa: E402
from benchmarks.peer_inversion import hoelscher, sader_jarvis_katan  # noqa: E402
from simulator import RK4, Cantilever, Scales, System, TipExcitation  # noqa: E402
from simulator.forces import (  # noqa: E402
    DMT,
    Electrostatic,
    ExponentialDamping,
    ForceSum,
    HystereticJKR,
    ViscoelasticDMT,
)
from simulator.lockin import LockIn  # noqa: E402
from simulator.scenarios.lockin import LockInCurve  # noqa: E402

CAUSES = ("none", "contact_geometry", "viscoelastic", "long_range_damping", "electrostatic",
          "adhesion_hysteresis", "drift")
K, F0, Q = 2.7, 72350.0, 187.0
L_REF = 10e-9
R_TIP = 10e-9
A0 = 0.3e-9
BANDWIDTH_HZ = 1000.0
#: uniform turning-point grid of the peer inversions (about 3 curve points per bin)
PEER_BINS = 50
#: lower turning point at the ramp's start (/ L_REF): 10 nm from the surface. Not free for a
#: strong electrostatic tail at a small free amplitude (session 8: at 8 nm free amplitude the
#: amplitude there is 16 % below free and the phase 35 deg off), which breaks the fit's
#: contract that the ramp's far end is free (``--lead-in``)
LEAD_IN = 1.0


def make_case(cause: str, index: int, seed: int, periods: float, every: int, *,
              free_amplitude: float | None = None, member: int = 0,
              lead_in: float = LEAD_IN) -> dict:
    """Simulate one curve; returns the analysis input and the truth (kept apart).

    ``free_amplitude`` (/ ``L_REF``) replaces the drawn one (every other draw is unchanged:
    the same tip and sample) and ``member`` != 0 changes only the noise seed: the curves of
    one tip at several free amplitudes (``--group``). The ramp starts with its lower turning
    point ``lead_in`` (/ ``L_REF``) from the surface; a longer lead-in than ``LEAD_IN`` adds
    drive periods in proportion (same ramp speed: the same curve with a longer free part in
    front)."""
    rng = np.random.default_rng([seed, CAUSES.index(cause), index])
    sc = Scales(K, F0, L_REF)
    ham = rng.uniform(0.5, 1.5) * 1e-19
    e_star = 10.0 ** rng.uniform(9.0, 10.0)
    base = {"hamaker_j": ham, "tip_radius_m": R_TIP, "reduced_modulus_pa": e_star,
            "a0_m": A0, "scales": sc}
    drift = 0.0
    if cause == "contact_geometry":
        force = DMT.from_si(**base, exponent=2.0,
                            contact_coefficient=10.0 ** rng.uniform(8.5, 9.5))
    elif cause == "viscoelastic":
        force = ViscoelasticDMT.from_si(**base, exponent=1.5,
                                        viscosity_si=10.0 ** rng.uniform(-2.0, -1.0),
                                        viscosity_exponent=0.5)
    elif cause == "long_range_damping":
        force = ForceSum([DMT.from_si(**base), ExponentialDamping.from_si(
            coefficient_ns_per_m=10.0 ** rng.uniform(-7.7, -7.0),
            decay_length_m=rng.uniform(2e-9, 5e-9), scales=sc)])
    elif cause == "electrostatic":
        force = ForceSum([DMT.from_si(**base), Electrostatic.from_si(
            voltage_v=rng.uniform(2.0, 4.0), tip_radius_m=R_TIP, scales=sc)])
    elif cause == "adhesion_hysteresis":
        force = HystereticJKR.from_si(work_of_adhesion_j_per_m2=rng.uniform(0.05, 0.15),
                                      reduced_modulus_pa=e_star, a0_m=A0, tip_radius_m=R_TIP,
                                      scales=sc)
    else:
        force = DMT.from_si(**base)
        if cause == "drift":
            # 0.5--1.5 nm over the whole ramp, either way
            drift = rng.uniform(0.5, 1.5) * rng.choice([-1.0, 1.0]) * 1e-9 / L_REF
    free = rng.uniform(1.5, 3.0)  # free amplitude 15--30 nm
    if free_amplitude is not None:
        free = float(free_amplitude)
    cl = Cantilever.rectangular(n_modes=1, quality_factor=Q)
    system = System(cl, force, TipExcitation.for_free_amplitude(cl, 1.0, free))
    dt_out = every * 2.0 * math.pi
    lockin = LockIn(bandwidth=BANDWIDTH_HZ / F0, order=4, output_interval=dt_out)
    gap_end = free * rng.uniform(0.25, 0.45)
    periods *= (free + lead_in - gap_end) / (free + LEAD_IN - gap_end)
    drift /= 2.0 * periods * 2.0 * math.pi  # the drawn total over the whole ramp
    scen = LockInCurve(gap_start=free + lead_in, gap_end=gap_end, n_periods=periods,
                       lockin=lockin, amplitude_noise=0.01, phase_noise=math.radians(0.5),
                       drift=drift, seed=(int(rng.integers(2**31)) + 7919 * member) % 2**31,
                       samples_per_period=40,
                       integrator=RK4(steps_per_period=120))
    rec = scen.run(system).meta["curve"]
    ell = L_REF
    data = {"amplitude_m": rec.amplitude * ell, "phase_rad": rec.phase,
            "z_piezo_m": rec.z_piezo * ell, "segment": rec.segment,
            "sample_rate_hz": F0 / every}
    truth = {"force": force, "rest_gap_m": rec.rest_gap * ell, "free_amplitude_m":
             rec.free_amplitude * ell, "lockin": lockin}
    return {"data": data, "truth": truth}


def force_errors(diag: CurveDiagnoser, data: dict, truth: dict) -> dict:
    """Conservative-force NRMSE of afmlearn and the peers on the approach's interaction zone.

    The grid is uniform between the 5th and 95th percentiles of the measured lower turning
    points ``D = d - A`` where the amplitude is below 97 % of free; the peers get the true
    rest gap and drive, and amplitude and phase smoothed along the ramp (Savitzky--Golay,
    9 points, quadratic) and binned onto ``PEER_BINS`` turning points, as one would before
    differentiating measured curves.
    """
    curve = diag.curve_
    app = data["segment"] == 0
    amp = data["amplitude_m"][app]
    ph = data["phase_rad"][app]
    gap = truth["rest_gap_m"][app]
    a_f = truth["free_amplitude_m"]
    zone = amp < 0.97 * a_f
    if zone.sum() < 10:
        return {"afmlearn": math.nan, "sjk": math.nan, "hoelscher": math.nan, "n_zone": 0}
    nm = 1e9
    d_zone = (gap - amp)[zone] * nm
    grid = np.linspace(np.percentile(d_zone, 5), np.percentile(d_zone, 95), 100)
    f_true = truth["force"](grid * 1e-9 / L_REF, 0.0) * K * L_REF * nm  # nN
    amp_s = signal.savgol_filter(amp, 9, 2)
    ph_s = signal.savgol_filter(ph, 9, 2)
    out = {}
    for name, fn in (("sjk", sader_jarvis_katan), ("hoelscher", hoelscher)):
        dd, f = fn(gap * nm, amp_s * nm, ph_s, omega=1.0, drive=a_f / Q * nm, n_bins=PEER_BINS)
        keep = np.concatenate([[True], np.diff(dd) > 0])
        f_peer = np.interp(grid, dd[keep], f[keep]) * K  # k nm -> nN
        out[name] = nrmse(f_peer, f_true)
        out.update(_by_region(name, f_peer, f_true, grid))
    ext = diag.extended_
    f_fit = ext.law_.conservative(grid * 1e-9 / curve.length_m) * curve.force_unit_n * nm
    out["afmlearn"] = nrmse(f_fit, f_true)
    out.update(_by_region("afmlearn", f_fit, f_true, grid))
    out["n_zone"] = int(zone.sum())
    out["grid_nm"] = [float(grid[0]), float(grid[-1])]
    return out


def _by_region(name: str, f: np.ndarray, f_true: np.ndarray, grid_nm: np.ndarray) -> dict:
    """RMS force error in contact (turning point below ``A0``) and out of contact, each over
    the whole grid's force range (the two parts are comparable with the whole NRMSE)."""
    scale = float(np.ptp(f_true))
    out = {}
    for region, m in (("contact", grid_nm < A0 * 1e9), ("attractive", grid_nm >= A0 * 1e9)):
        out[f"{name}_{region}"] = (nrmse(f[m], f_true[m], scale=scale)
                                   if m.any() and scale > 0 else math.nan)
    return out


def run_one(job: dict) -> dict:
    t0 = time.perf_counter()
    case = make_case(job["cause"], job["index"], job["seed"], job["periods"], job["every"])
    t_sim = time.perf_counter() - t0
    d = case["data"]
    curve = Curve.from_si(amplitude_m=d["amplitude_m"], phase_rad=d["phase_rad"],
                          z_piezo_m=d["z_piezo_m"], segment=d["segment"],
                          sample_rate_hz=d["sample_rate_hz"], quality_factor=Q,
                          spring_constant_n_per_m=K, resonance_frequency_hz=F0)
    t1 = time.perf_counter()
    diag = CurveDiagnoser(lockin=case["truth"]["lockin"],
                          max_evaluations=job.get("max_evaluations")).fit(curve)
    t_fit = time.perf_counter() - t1
    errs = force_errors(diag, d, case["truth"])
    return {**job, "named": diag.cause_, "gain": diag.gain_, "confidence": diag.confidence_,
            "candidates": diag.candidates_, "errors": errs, "t_sim": t_sim, "t_fit": t_fit,
            "n_evaluations": diag.n_evaluations_, "exposure": exposure(d, case["truth"]),
            "law": diag.extended_.values_, "baseline_chi2": diag.baseline_.chi2_}


def exposure(data: dict, truth: dict) -> dict:
    """How much of the approach exercises the contact (from the truth, for the report only).

    ``indentation_nm``: deepest lower turning point past the contact onset ``a0``;
    ``touch_fraction``: share of approach samples whose turning point passes ``a0``;
    ``repulsive_end``: the approach ends on the repulsive branch (lag below 90 deg).
    """
    app = data["segment"] == 0
    low = (truth["rest_gap_m"] - data["amplitude_m"])[app]
    return {"indentation_nm": float(max(0.0, (A0 - low.min()) * 1e9)),
            "touch_fraction": float(np.mean(low < A0)),
            "repulsive_end": bool(data["phase_rad"][app][-1] < math.pi / 2)}


def truth_values(cause: str, truth: dict, data: dict, curve: Curve) -> dict | None:
    """The true law in the fitter's parameters (curve units), or None when the cause's law is
    not a :class:`CurveLaw` (the JKR neck). For the oracle only."""
    r = curve.length_m / L_REF
    force = truth["force"]
    terms = list(force.terms) if isinstance(force, ForceSum) else [force]
    out: dict = {"offset": float(data["z_piezo_m"][0] - truth["rest_gap_m"][0]) / curve.length_m}
    for t in terms:
        if isinstance(t, HystereticJKR):
            return None
        p = t.parameters()
        if "stiffness" in p:
            out.update(vdw=p["vdw"] / r**3, stiffness=p["stiffness"] * r ** (p["exponent"] - 1))
            if cause == "contact_geometry":
                out["exponent"] = p["exponent"]
        if "viscosity" in p:
            out["visco"] = p["viscosity"] * r**0.5
        if "coefficient" in p:
            out.update(damping=p["coefficient"], decay_length=p["decay_length"] / r)
        if "strength" in p:
            out["electrostatic"] = p["strength"] / r**3
    if cause == "drift":
        gap = truth["rest_gap_m"] / curve.length_m
        zp = data["z_piezo_m"] / curve.length_m
        out["drift"] = float(np.polyfit(curve.tau, gap - zp, 1)[0])
    return out


def oracle(job: dict, rec: dict) -> dict:
    """Evidence the TRUE law carries on this curve: the cause's extension refined from the
    truth, against the diagnoser's baseline chi-square (recovered from a candidate). An
    evidence below the naming threshold means the effect is not observable on this curve at
    this noise; a truth-started baseline below the diagnoser's means its baseline was stuck."""
    case = make_case(job["cause"], job["index"], job["seed"], job["periods"], job["every"])
    d = case["data"]
    curve = Curve.from_si(amplitude_m=d["amplitude_m"], phase_rad=d["phase_rad"],
                          z_piezo_m=d["z_piezo_m"], segment=d["segment"],
                          sample_rate_hz=d["sample_rate_hz"], quality_factor=Q,
                          spring_constant_n_per_m=K, resonance_frequency_hz=F0)
    vals = truth_values(job["cause"], case["truth"], d, curve)
    out = {"cause": job["cause"], "index": job["index"], "seed": job["seed"],
           "periods": job["periods"]}
    if vals is None:
        return {**out, "evidence": None}
    n = 2 * int(np.sum(curve.segment == 0))
    c0 = rec["candidates"][0]
    k0 = len(next(h for h in EXTENSIONS if h.cause == c0["cause"]).parameters)
    b_chi2 = c0["chi2"] * math.exp((c0["evidence"] + k0 * math.log(n)) / n)
    hyp = next((h for h in EXTENSIONS if h.cause == job["cause"]), None)
    fit = CurveFitter(hypothesis=hyp, start=vals, rescales=((1.0, 1.0),),
                      lockin=case["truth"]["lockin"]).fit(curve)
    k = len(hyp.parameters) if hyp is not None else 0
    ev = n * math.log(b_chi2 / fit.chi2_) - k * math.log(n)
    return {**out, "evidence": float(ev), "chi2_truth": float(fit.chi2_),
            "chi2_baseline": float(b_chi2)}


def load(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _regions(rs: list[dict]) -> str:
    """Median force errors of afmlearn and the SJ peer in and out of contact (records of this
    benchmark version; blank for older records)."""
    parts = []
    for region in ("contact", "attractive"):
        a = np.array([r["errors"].get(f"afmlearn_{region}", math.nan) for r in rs], dtype=float)
        b = np.array([r["errors"].get(f"sjk_{region}", math.nan) for r in rs], dtype=float)
        ok = np.isfinite(a) & np.isfinite(b)
        parts.append(f"{fmt(np.median(a[ok]))} / {fmt(np.median(b[ok]))}" if ok.any() else "")
    return "; ".join(parts) if any(parts) else ""


def section(recs: list[dict], args, oracles: dict | None = None) -> str:
    oracles = oracles or {}
    rows = []
    ratios = []
    seen = []
    for cause in CAUSES:
        rs = [r for r in recs if r["cause"] == cause]
        if not rs:
            continue
        acc = np.mean([r["named"] == cause for r in rs])
        ea = np.array([r["errors"]["afmlearn"] for r in rs], dtype=float)
        es = np.array([r["errors"]["sjk"] for r in rs], dtype=float)
        eh = np.array([r["errors"]["hoelscher"] for r in rs], dtype=float)
        ok = np.isfinite(ea) & np.isfinite(es)
        ratio = np.nanmedian(ea[ok] / es[ok]) if ok.any() else math.nan
        ratios += list(ea[ok] / es[ok])
        named = ", ".join(f"{c}:{n}" for c, n in sorted(
            {c: sum(r["named"] == c for r in rs) for c in {r["named"] for r in rs}}.items()))
        ex = [r.get("exposure") for r in rs if r.get("exposure")]
        touch = (f"{sum(e['touch_fraction'] > 0 for e in ex)}/{len(ex)}, "
                 f"{fmt(np.median([e['indentation_nm'] for e in ex]))} nm, "
                 f"{sum(e['repulsive_end'] for e in ex)}" if ex else "")
        obs = [oracles.get((r["cause"], r["index"])) for r in rs]
        obs = [(o["evidence"] is not None and o["evidence"] > 10.0, r["named"] == cause)
               for o, r in zip(obs, rs, strict=True)
               if o is not None and o["evidence"] is not None]
        seen += obs
        n_obs = sum(v for v, _ in obs)
        observable = (f"{n_obs}/{len(obs)}; {sum(v and ok for v, ok in obs)}/{n_obs}"
                      if obs else "")
        rows.append([cause, len(rs), f"{100 * acc:.0f} %", observable, touch,
                     fmt(np.nanmedian(ea)),
                     fmt(np.nanmedian(es)), fmt(np.nanmedian(eh)), fmt(ratio), _regions(rs),
                     fmt(np.median([r["t_fit"] for r in rs]), 3), named])
    allr = np.array(ratios)
    acc_all = np.mean([r["named"] == r["cause"] for r in recs])
    head = ["cause (hidden)", "curves", "named right",
            "truth's own evidence > 10 (oracle); of those named right",
            "tip touched, median indentation, ended repulsive (truth)", "force NRMSE afmlearn",
            "force NRMSE peer (Katan/Payam SJ)", "force NRMSE peer (Hoelscher)",
            "median ratio afmlearn / SJ",
            "median force error afmlearn / SJ in contact; out of contact (each over the whole "
            "force range)", "fit time [s]", "named as"]
    text = [
        f"{len(recs)} synthetic curves ({args.per_cause} per cause requested), "
        f"{args.periods:g} drive periods per ramp, output every {args.every} periods, "
        f"lock-in 4th order {BANDWIDTH_HZ:g} Hz, 1 % amplitude and 0.5 deg phase noise, "
        "lever k 2.7 N/m, f0 72.35 kHz, Q 187 (Asylum-like); forces on the approach's "
        "interaction zone (amplitude < 97 % of free).", "",
        md_table(head, rows), "",
        f"Overall cause accuracy {100 * acc_all:.1f} %; afmlearn's force error is "
        f"{fmt(np.nanmedian(allr))} x the Katan/Payam Sader--Jarvis inversion's (median over "
        f"curves; goal <= 0.5), <= 0.5 x on {100 * np.mean(allr <= 0.5):.0f} % of the curves. "
        "The peers are given the true surface position and drive."]
    if args.note:
        text += ["", args.note]
    return "\n".join(text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-cause", type=int, default=10)
    ap.add_argument("--periods", type=float, default=2000.0)
    ap.add_argument("--every", type=int, default=12, help="drive periods per output sample")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--causes", default=",".join(CAUSES))
    ap.add_argument("--records", default=str(ROOT / "outputs" / "bench_curves.jsonl"))
    ap.add_argument("--note", default="", help="a line appended to the section")
    ap.add_argument("--max-evaluations", type=int, default=None,
                    help="forward-model evaluations per curve (CurveDiagnoser cap)")
    ap.add_argument("--report-only", action="store_true",
                    help="no new curves: the section from the records so far")
    ap.add_argument("--oracle", action="store_true",
                    help="after the curves: the truth's own evidence per record (missed "
                         "ones first; resumable, <records>.oracle.jsonl)")
    ap.add_argument("--group", type=int, default=0,
                    help="N > 0: groups of N curves of one tip at several free amplitudes, "
                         "single-curve vs joint diagnosis (records <records>-groups.jsonl)")
    ap.add_argument("--joint-evaluations", type=int, default=4000,
                    help="--group: curve evaluations of each joint diagnosis")
    ap.add_argument("--free-span", default=",".join(f"{f:g}" for f in GROUP_FREE),
                    help="--group: smallest and largest free amplitude of a group (/ 10 nm)")
    ap.add_argument("--lead-in", type=float, default=LEAD_IN,
                    help="--group: lower turning point at the ramp's start (/ 10 nm); a longer "
                         "one adds periods in proportion (same ramp speed)")
    ap.add_argument("--hold-free-scale", action="store_true",
                    help="--group: hold every curve's free-amplitude scale at 1 in the joint "
                         "fits (sessions 4-8); default: fitted per curve")
    add_doc_flag(ap)
    args = ap.parse_args(argv)
    info = machine_info()
    if args.group > 0:
        return run_groups(args, info)
    path = Path(args.records)
    path.parent.mkdir(parents=True, exist_ok=True)
    done = {(r["cause"], r["index"]) for r in load(path)}
    jobs = [{"cause": c, "index": i, "seed": args.seed, "periods": args.periods,
             "every": args.every, "max_evaluations": args.max_evaluations}
            for i in range(args.per_cause) for c in args.causes.split(",")]
    order = np.random.default_rng(args.seed).permutation(len(jobs))
    for k in order:
        job = jobs[k]
        if args.report_only or (job["cause"], job["index"]) in done:
            continue
        rec = run_one(job)
        with open(path, "a") as fh:
            fh.write(json.dumps(rec) + "\n")
        print(f"{job['cause']:>20s} #{job['index']}: named {rec['named']:<20s} "
              f"err afm {rec['errors']['afmlearn']:.3f} sjk {rec['errors']['sjk']:.3f} "
              f"fit {rec['t_fit']:.1f} s", flush=True)
    recs = [r for r in load(path) if r["seed"] == args.seed and r["periods"] == args.periods]
    opath = path.with_suffix(".oracle.jsonl")
    if args.oracle:
        have = {(o["cause"], o["index"]) for o in load(opath)}
        for r in sorted(recs, key=lambda r: (r["named"] == r["cause"], r["cause"], r["index"])):
            if (r["cause"], r["index"]) in have:
                continue
            o = oracle(r, r)
            with open(opath, "a") as fh:
                fh.write(json.dumps(o) + "\n")
            print(f"oracle {r['cause']:>20s} #{r['index']}: evidence {o['evidence']}",
                  flush=True)
    oracles = {(o["cause"], o["index"]): o for o in load(opath)
               if o["seed"] == args.seed and o["periods"] == args.periods}
    write_section("curves", "Lock-in curves: force error vs the peer inversion, cause accuracy "
                  "(`bench_curves.py`)", section(recs, args, oracles), info,
                  write=not args.no_doc)
    return 0



# ---------------------------------------------------------------- --group N (joint fits)
#: free amplitudes (/ L_REF) of a group's curves span the single-curve range (15--30 nm)
GROUP_FREE = (1.5, 3.0)


def _curve_of(data: dict) -> Curve:
    return Curve.from_si(amplitude_m=data["amplitude_m"], phase_rad=data["phase_rad"],
                         z_piezo_m=data["z_piezo_m"], segment=data["segment"],
                         sample_rate_hz=data["sample_rate_hz"], quality_factor=Q,
                         spring_constant_n_per_m=K, resonance_frequency_hz=F0)


def run_group(job: dict) -> dict:
    """One group: N curves of one tip (same force law and ramp draws, free amplitudes spread
    over ``GROUP_FREE``), each diagnosed alone, then all jointly (seeded by the single fits).
    The analysis sees the curves only; the truth is used for the force errors."""
    from afmlearn.curves.group_diagnose import GroupDiagnoser, starts_from_singles

    n = job["group"]
    frees = np.linspace(*job.get("free_span", GROUP_FREE), n)
    cases = [make_case(job["cause"], job["index"], job["seed"], job["periods"], job["every"],
                       free_amplitude=float(f), member=m,
                       lead_in=job.get("lead_in", LEAD_IN)) for m, f in enumerate(frees)]
    curves = [_curve_of(c["data"]) for c in cases]
    lockin = cases[0]["truth"]["lockin"]
    t0 = time.perf_counter()
    singles = [CurveDiagnoser(lockin=lockin, max_evaluations=job.get("max_evaluations")
                              ).fit(c) for c in curves]
    t_single = time.perf_counter() - t0
    t1 = time.perf_counter()
    joint = GroupDiagnoser(lockin=lockin, max_evaluations=job["joint_evaluations"],
                           free_scale=job.get("free_scale", False)).fit(
        curves, extra_starts=starts_from_singles(singles))
    t_joint = time.perf_counter() - t1
    ext = joint.extended_
    members = []
    for i, (case, single) in enumerate(zip(cases, singles, strict=True)):
        adapter = SimpleNamespace(curve_=curves[i],
                                  extended_=SimpleNamespace(law_=ext.law_for(i)))
        members.append({"free_amplitude_m": curves[i].length_m, "named": single.cause_,
                        "gain": single.gain_,
                        "errors": force_errors(single, case["data"], case["truth"]),
                        "errors_joint": force_errors(adapter, case["data"], case["truth"]),
                        "exposure": exposure(case["data"], case["truth"])})
    return {**job, "named_joint": joint.cause_, "gain_joint": joint.gain_,
            "confidence_joint": joint.confidence_,
            "candidates_joint": [{k: v for k, v in c.items()} for c in joint.candidates_],
            "loo_joint": joint.loo_, "members": members, "t_single": t_single,
            "nuisances_joint": ext.values_["curves"],
            "t_joint": t_joint,
            "n_evaluations_joint": joint.n_evaluations_,
            "load": os.getloadavg()[0]}


def group_section(recs: list[dict], args, oracles: dict | None = None) -> str:
    """Single-curve vs joint cause accuracy and force error per cause (same curves), and the
    joint oracle: on how many groups the true law's own joint evidence exceeds 10."""
    oracles = oracles or {}
    rows = []
    all_single, all_joint, rs_single, rs_joint = [], [], [], []
    for cause in CAUSES:
        rs = [r for r in recs if r["cause"] == cause]
        if not rs:
            continue
        single = [m["named"] == cause for r in rs for m in r["members"]]
        joint = [r["named_joint"] == cause for r in rs]
        all_single += single
        all_joint += joint
        ratio_s = [m["errors"]["afmlearn"] / m["errors"]["sjk"] for r in rs
                   for m in r["members"]]
        ratio_j = [m["errors_joint"]["afmlearn"] / m["errors_joint"]["sjk"] for r in rs
                   for m in r["members"]]
        rs_single += ratio_s
        rs_joint += ratio_j
        named = ", ".join(f"{c}:{k}" for c, k in sorted(
            {c: sum(r["named_joint"] == c for r in rs)
             for c in {r["named_joint"] for r in rs}}.items()))
        gains = [r["gain_joint"] for r in rs if r["named_joint"] == cause]
        agree = sum(len({m["named"] for m in r["members"]}) == 1 for r in rs)
        obs = [(o["evidence"] > 10.0, r["named_joint"] == cause) for r in rs
               if (o := oracles.get((r["cause"], r["index"]))) is not None
               and o["evidence"] is not None]
        n_obs = sum(v for v, _ in obs)
        observable = (f"{n_obs}/{len(obs)}; {sum(v and ok for v, ok in obs)}/{n_obs}"
                      if obs else "")
        rows.append([cause, len(rs), f"{sum(single)}/{len(single)}", f"{agree}/{len(rs)}",
                     f"{sum(joint)}/{len(joint)}", observable, fmt(np.nanmedian(ratio_s)),
                     fmt(np.nanmedian(ratio_j)),
                     fmt(np.median(gains)) if gains else "",
                     fmt(np.median([r["t_single"] for r in rs]), 3),
                     fmt(np.median([r["t_joint"] for r in rs]), 3), named])
    head = ["cause (hidden)", "groups", "single-curve named right (curves)",
            "single: one cause on all curves of the group", "joint named right (groups)",
            "truth's own joint evidence > 10 (oracle); of those named right",
            "force error / SJ peer, single (median)",
            "force error / SJ peer, joint (median)", "leave-one-out gain (joint, named right)",
            "single fits per group [s]", "joint fit [s]", "joint named as"]
    loads = [r["load"] for r in recs if r.get("load") is not None]
    rj = np.array(rs_joint, dtype=float)
    lead = ("" if args.lead_in == LEAD_IN else
            f" (the ramp starts with the lower turning point "
            f"{args.lead_in * 10:g} nm from the surface instead of {LEAD_IN * 10:g} nm; periods "
            "added in proportion)")
    text = [
        f"{len(recs)} groups of {args.group} curves of one tip (same force law and ramp, free "
        f"amplitudes {args.span[0] * 10:g}--{args.span[1] * 10:g} nm evenly spread, noise "
        f"seeds differ), {args.periods:g} drive periods per ramp{lead}, 1 % amplitude and "
        "0.5 deg "
        f"phase noise, lever as the single-curve section. Single: `CurveDiagnoser` per curve "
        f"(max_evaluations {args.max_evaluations}); joint: `GroupDiagnoser` "
        f"(max_evaluations {args.joint_evaluations}, seeded by the single fits), gain = "
        f"leave-one-curve-out. Median load during the runs "
        f"{fmt(np.median(loads)) if loads else 'n/a'} (2 cores shared).", "",
        md_table(head, rows), "",
        f"Overall: single-curve {100 * np.mean(all_single):.1f} % of curves, joint "
        f"{100 * np.mean(all_joint):.1f} % of groups named right; joint force error "
        f"{fmt(np.nanmedian(rj))} x the Katan/Payam SJ inversion's (median over curves), "
        f"<= 0.5 x on {100 * np.mean(rj[np.isfinite(rj)] <= 0.5):.0f} % (single: "
        f"{fmt(np.nanmedian(rs_single))} x)."]
    misses = [miss_class(r, oracles.get((r["cause"], r["index"]))) for r in recs
              if r["named_joint"] != r["cause"]]
    if misses:
        text += ["", "Misses (joint): " + "; ".join(misses) + "."]
    if args.note:
        text += ["", args.note]
    return "\n".join(text)


#: evidence (BIC units) above which a cause can be named (GroupDiagnoser's default threshold)
NAMING_THRESHOLD = 10.0


def miss_class(rec: dict, oracle: dict | None) -> str:
    """Why a group's joint diagnosis missed its cause, in one phrase.

    ``invisible``: the true law's own joint evidence (oracle) is at most the naming threshold,
    whatever the optimiser does (only when the truth-started fit reaches the baseline's chi2:
    else the oracle is a lower bound and says nothing); ``fit``: the fitted extension of the
    true cause stays at or below the threshold although the truth is above it (or, without an
    informative oracle, below it: fit or invisible); ``decision``: the true cause's fitted
    evidence is above the threshold but its left-out gain refutes it (<= 0) or another
    eligible cause has more evidence.
    """
    cause = rec["cause"]
    cand = next((c for c in rec["candidates_joint"] if c["cause"] == cause), None)
    ev_o = None if oracle is None else oracle.get("evidence")
    head = f"{cause} #{rec['index']} named {rec['named_joint']}"
    if cand is None:  # ``none`` named something: a false positive
        top = rec["candidates_joint"][0]
        return (f"{head} (false positive: evidence {fmt(top['evidence'])}, left-out gain "
                f"{fmt(top['gain'])})")
    ev, gain = cand["evidence"], cand["gain"]
    what = f"evidence {fmt(ev)}, left-out gain {fmt(gain) if gain is not None else 'n/a'}"
    truth = "" if ev_o is None else f", truth {fmt(ev_o)}"
    if ev_o is not None and oracle["chi2_truth"] > oracle["chi2_baseline"]:
        # the extension nests the baseline: a truth-started fit above the fitted baseline is
        # not at its optimum, its evidence only a lower bound that cannot say "invisible"
        ev_o, truth = None, f", truth-started fit stuck at {fmt(oracle['evidence'])}"
    if ev_o is not None and ev_o <= NAMING_THRESHOLD and ev <= NAMING_THRESHOLD:
        return f"{head}: invisible ({what}{truth})"
    if ev <= NAMING_THRESHOLD:
        kind = "fit" if ev_o is not None else "fit or invisible"
        return f"{head}: {kind} ({what}{truth})"
    why = "refuted" if gain is not None and gain <= 0.0 else "outranked"
    return f"{head}: decision, {why} ({what}{truth})"


def run_groups(args, info: dict) -> int:
    """``--group N``: resumable group records and the "curve_groups" docs section."""
    path = Path(args.records).with_name(Path(args.records).stem + "-groups.jsonl")
    path.parent.mkdir(parents=True, exist_ok=True)
    span = [float(f) for f in args.free_span.split(",")]
    if len(span) != 2 or not 0.0 < span[0] < span[1]:
        raise SystemExit(f"--free-span must be LO,HI with 0 < LO < HI, got {args.free_span!r}")
    args.span = tuple(span)

    def same(r: dict) -> bool:  # records of this setting (older records: the default span)
        return (r["seed"] == args.seed and r["periods"] == args.periods
                and r["group"] == args.group
                and tuple(r.get("free_span", GROUP_FREE)) == args.span
                and (r.get("lead_in") or LEAD_IN) == args.lead_in
                and r.get("free_scale", False) == (not args.hold_free_scale))

    done = {(r["cause"], r["index"], r["group"]) for r in load(path) if same(r)}
    causes = args.causes.split(",")
    rng = np.random.default_rng(args.seed)
    for i in range(args.per_cause):  # every cause's group i before any group i + 1
        for c in rng.permutation(causes):
            job = {"cause": str(c), "index": i, "seed": args.seed, "periods": args.periods,
                   "every": args.every, "max_evaluations": args.max_evaluations,
                   "group": args.group, "joint_evaluations": args.joint_evaluations,
                   "free_span": list(args.span), "lead_in": args.lead_in,
                   "free_scale": not args.hold_free_scale}
            if args.report_only or (job["cause"], i, args.group) in done:
                continue
            rec = run_group(job)
            with open(path, "a") as fh:
                fh.write(json.dumps(rec) + "\n")
            print(f"{job['cause']:>20s} group #{i}: single "
                  f"{[m['named'] for m in rec['members']]} joint {rec['named_joint']} "
                  f"({rec['t_single']:.0f} s + {rec['t_joint']:.0f} s)", flush=True)
    recs = [r for r in load(path) if same(r)]
    opath = path.with_suffix(".oracle.jsonl")
    if args.oracle:
        have = {(o["cause"], o["index"]) for o in load(opath) if same(o)}
        for r in sorted(recs, key=lambda r: (r["named_joint"] == r["cause"], r["cause"],
                                             r["index"])):
            if (r["cause"], r["index"]) in have:
                continue
            o = group_oracle(r)
            with open(opath, "a") as fh:
                fh.write(json.dumps(o) + "\n")
            print(f"joint oracle {r['cause']:>20s} #{r['index']}: evidence {o['evidence']}",
                  flush=True)
    oracles = {(o["cause"], o["index"]): o for o in load(opath) if same(o)}
    # another amplitude span gets its own section (the default span's results stay)
    wide = args.span != GROUP_FREE
    lead = args.lead_in != LEAD_IN
    # the fitted free-amplitude scales (session 9) get their own sections
    scaled = not args.hold_free_scale
    write_section("curve_groups" + ("_wide" if wide else "") + ("_lead" if lead else "")
                  + ("_scaled" if scaled else ""),
                  "Lock-in curves: joint fit across free amplitudes vs single curves "
                  f"(`bench_curves.py --group`{' --free-span' if wide else ''}"
                  f"{' --lead-in' if lead else ''})",
                  group_section(recs, args, oracles), info, write=not args.no_doc)
    return 0


def group_oracle(job: dict) -> dict:
    """The joint evidence the TRUE law carries on a group: the cause's extension fitted
    jointly from the truth (law, surface positions; drive from the free phase), against the joint
    diagnosis' baseline chi-square (recovered from a candidate). Below the naming threshold:
    the effect is not observable on these curves at this noise, whatever the optimiser does;
    None for the JKR neck (not a ``CurveLaw``)."""
    from afmlearn.curves.group import GroupFitter

    n = job["group"]
    frees = np.linspace(*job.get("free_span", GROUP_FREE), n)
    cases = [make_case(job["cause"], job["index"], job["seed"], job["periods"], job["every"],
                       free_amplitude=float(f), member=m,
                       lead_in=job.get("lead_in", LEAD_IN)) for m, f in enumerate(frees)]
    curves = [_curve_of(c["data"]) for c in cases]
    keys = ("cause", "index", "seed", "periods", "group", "free_span", "lead_in", "free_scale")
    out = {k: job.get(k) for k in keys}
    vals = [truth_values(job["cause"], c["truth"], c["data"], cv)
            for c, cv in zip(cases, curves, strict=True)]
    if vals[0] is None:
        return {**out, "evidence": None}
    hyp = next((h for h in EXTENSIONS if h.cause == job["cause"]), None)
    lockins = [c["truth"]["lockin"] for c in cases]
    law = {k: v for k, v in vals[0].items() if k not in ("offset", "drift")}
    # the true law in the slow-flow model is not the model's optimum (averaging, filter): each
    # curve's surface position and drive are first fitted under the true law held fixed (a
    # scan: the jump's valley is a fraction of a nanometre wide), then everything is refined
    unit = curves[0].length_m
    fixed = CurveLaw(a0=A0 / unit, radius=R_TIP / unit).replace(**law)
    drift = next((h for h in EXTENSIONS if h.cause == "drift"), None)
    # the diagnosis' nuisances: each curve's free-amplitude scale where it fits them
    scale = bool(job.get("free_scale", False))
    nuis = GroupFitter(hypothesis=drift if job["cause"] == "drift" else None,
                       fixed_law=(fixed, unit), lockins=lockins, free_scale=scale).fit(curves)
    start = {"law": law, "length_m": unit, "curves": nuis.values_["curves"]}
    fit = GroupFitter(hypothesis=hyp, start=start, rescales=((1.0, 1.0),), max_nfev=40,
                      lockins=lockins, free_scale=scale).fit(curves)
    c0 = job["candidates_joint"][0]
    m = fit.n_fit_
    b_chi2 = c0["chi2"] * math.exp((c0["evidence"] + c0["n_parameters"] * math.log(m)) / m)
    k = 0 if hyp is None else sum(n if p.field == "drift" else 1 for p in hyp.parameters)
    ev = m * math.log(b_chi2 / fit.chi2_) - k * math.log(m)
    return {**out, "evidence": float(ev), "chi2_truth": float(fit.chi2_),
            "chi2_baseline": float(b_chi2), "n_fit": m}


if __name__ == "__main__":
    raise SystemExit(main())
