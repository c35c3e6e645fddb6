"""Sweet-spot acceptance study: the 2-mode Table 3.B.1 model swept as in the dissertation.

Forward and reverse sweeps over ``Omega = 0.990149 ... 1.1327`` (501 points x 50,000 samples at
1,500 samples per free period, ``dt = 2 pi / 1500``; ``simulator.Sweep`` with its default
settling of 2.5 Q1 periods at the first frequency), for the 2-mode model and, for comparison,
the 1-mode model with the same mode-1 numbers. Per sweep point it records (definitions in
``docs/sweet_spot.md``): max/min tip deflection, minimum gap and indentation, the tip
deflection's 1st and 6th harmonic amplitudes, the coupling strength (share of mode 2), the
contact fraction, and the mode phase difference ``phi_2(6 Omega) - 6 phi_1(Omega)``.

Writes ``docs/figures/sweet_spot.png`` (+ ``sweet_spot_orbits.png``) and the generated result
sections of ``docs/sweet_spot.md``. With ``--explore`` it first sweeps several values of the
unprinted van der Waals coefficient ``C1`` (``docs/figures/sweet_spot_c1.png`` and a table).

Run: ``python benchmarks/sweet_spot.py [--explore] [--c1 5e-4] [--points 501]
[--samples 50000]``
"""

from __future__ import annotations

import argparse
import math
import pickle
import re
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import _common as C  # first: puts the repository root on sys.path
import numpy as np
from _systems import A0, OMEGA_START, OMEGA_STOP, SAMPLES_PER_PERIOD, VDW_C1, system

from simulator import RK4, Sweep

DOC = C.ROOT / "docs" / "sweet_spot.md"
FIG = C.ROOT / "docs" / "figures"
#: f0 of the NCLR experiment (ch. 3) to convert its kHz to Omega = f / f0
F0_KHZ = 164.52
#: experiment (ch. 3): sweet spot 165-166 kHz, "beyond" 167 kHz
EXP_SWEET = (165.0 / F0_KHZ, 166.0 / F0_KHZ)
EXP_BEYOND = 167.0 / F0_KHZ
C1_GRID = (0.0, 1e-4, 3e-4, 4e-4, 5e-4, 6e-4, 7e-4, 1e-3, 2e-3, 3e-3)
#: C1 values rerun with a halved RK4 step (``--robustness``)
ROBUST_C1 = (5e-4, 6e-4, 7e-4)
#: the phase difference is reported only where the 6 Omega component of mode 2 is locked to
#: the drive: its value from the two halves of the point differs by less than this [deg] ...
LOCK_DEG = 15.0
#: ... and its amplitude exceeds this (units of the rest gap)
LOCK_MIN_AMP = 1e-3

KEYS = ("omega", "xmax", "xmin", "min_gap", "indentation", "a1", "a6", "a6_q2", "coupling",
        "contact", "dphi", "locked")


def lock_ins(y: np.ndarray, e1: np.ndarray, e6: np.ndarray) -> tuple[complex, complex]:
    """``x ~ Re(A_h e^{i h theta})`` for h = 1, 6 (``e_h = exp(-i h theta)``)."""
    return complex(2.0 * np.mean(y * e1)), complex(2.0 * np.mean(y * e6))


def point_features(q: np.ndarray, phase: np.ndarray, omega: float, labels: dict) -> dict:
    """Features of one sweep point; ``q`` (n_modes, n), ``phase`` (n,) drive phase."""
    x = q.sum(axis=0)
    n_per = SAMPLES_PER_PERIOD / omega
    n = int(math.floor(x.size / n_per) * n_per)  # whole drive periods
    x, q, ph = x[:n], q[:, :n], phase[:n]
    e1 = np.exp(-1j * ph)
    e3 = e1 * e1 * e1
    e6 = e3 * e3
    a1, a6 = lock_ins(x, e1, e6)
    out = {"omega": omega, "xmax": float(x.max()), "xmin": float(x.min()),
           "min_gap": labels["min_gap"], "indentation": max(A0 - labels["min_gap"], 0.0),
           "a1": abs(a1), "a6": abs(a6), "coupling": labels["coupling_strength"],
           "contact": labels["contact_fraction"], "a6_q2": 0.0, "dphi": math.nan,
           "locked": 0.0}
    if q.shape[0] > 1:
        def dphi(sl: slice) -> tuple[float, float]:
            p1, _ = lock_ins(q[0, sl], e1[sl], e6[sl])
            _, p6 = lock_ins(q[1, sl], e1[sl], e6[sl])
            return math.degrees(np.angle(p6 * np.conj(p1) ** 6)), abs(p6)

        d, amp = dphi(slice(None))
        half = int(math.floor(n / n_per / 2) * n_per)
        da, _ = dphi(slice(0, half))
        db, _ = dphi(slice(half, 2 * half))
        locked = abs((da - db + 180.0) % 360.0 - 180.0) < LOCK_DEG and amp > LOCK_MIN_AMP
        out.update(a6_q2=amp, dphi=abs(d), locked=float(locked))
    return out


@dataclass
class SweepData:
    """Per-point features of both directions (arrays in forward-frequency order)."""

    n_modes: int
    c1: float
    fwd: dict = field(default_factory=dict)
    rev: dict = field(default_factory=dict)
    orbits: dict = field(default_factory=dict)
    seconds: float = 0.0


CACHE = Path(tempfile.gettempdir()) / "afmlearn-sweet-spot-cache"
#: fingerprint of the simulator source this process runs (taken at import)
SOURCE = C.source_hash("simulator/integrate/_kernel.py", "simulator/forces/_kernel.py",
                       "simulator/scenarios/sweep.py", "benchmarks/_systems.py")


def run_sweep(n_modes: int, c1: float, *, points: int, samples: int,
              orbit_omegas: tuple[float, ...] = (), cache: bool = False,
              substeps: int | None = None) -> SweepData:
    """Sweep both directions and extract the features (cached per simulator source if asked).

    ``substeps``: RK4 steps per sample (None: the automatic choice, 1 here).
    """
    key = (f"{n_modes}_{c1:g}_{points}_{samples}_{substeps}_"
           f"{'-'.join(f'{w:g}' for w in orbit_omegas)}_{SOURCE}")
    path = CACHE / f"{key}.pkl"
    if cache and path.exists():
        with path.open("rb") as fh:
            return pickle.load(fh)
    data = _run_sweep(n_modes, c1, points=points, samples=samples, orbit_omegas=orbit_omegas,
                      substeps=substeps)
    if cache:
        CACHE.mkdir(exist_ok=True)
        with path.open("wb") as fh:
            pickle.dump(data, fh)
    return data


def _run_sweep(n_modes: int, c1: float, *, points: int, samples: int,
               orbit_omegas: tuple[float, ...], substeps: int | None) -> SweepData:
    s = system(n_modes, vdw=c1)
    sw = Sweep(omega_start=OMEGA_START, omega_stop=OMEGA_STOP, n_points=points,
               samples_per_point=samples, samples_per_period=SAMPLES_PER_PERIOD,
               direction="both", integrator=RK4(substeps=substeps))
    grid = sw.omegas
    want = {int(np.argmin(abs(grid - w))) for w in orbit_omegas}
    rows: dict[str, list] = {"forward": [None] * points, "reverse": [None] * points}
    data = SweepData(n_modes, c1)
    t0 = time.perf_counter()
    for p in sw.iter_points(s):
        k = p.row % points
        i = k if p.direction == "forward" else points - 1 - k
        rows[p.direction][i] = point_features(p.q, p.phase, p.omega, p.labels)
        if p.direction == "forward" and i in want:
            m = int(2 * SAMPLES_PER_PERIOD / p.omega)
            data.orbits[p.omega] = (p.q[:, -m:].copy(), p.gap[-m:].copy())
    data.seconds = time.perf_counter() - t0
    for d, target in (("forward", data.fwd), ("reverse", data.rev)):
        for key in KEYS:
            target[key] = np.array([r[key] for r in rows[d]])
    return data


def nearest(d: dict, omega: float) -> int:
    return int(np.argmin(abs(d["omega"] - omega)))


def summarize(data: SweepData) -> dict:
    """Jumps, the model's sweet-spot window and the numbers compared with the experiment."""
    out = {}
    for name, d in (("fwd", data.fwd), ("rev", data.rev)):
        high = d["contact"] > 0
        om = d["omega"]
        i1 = nearest(d, 1.0)
        out[f"{name}_tap"] = (float(om[high].min()), float(om[high].max())) if high.any() else None
        out[f"{name}_ref"] = i1
        out[f"{name}_a6_ratio_max"] = float(d["a6"].max() / d["a6"][i1])
        out[f"{name}_a6_ratio_at"] = float(om[int(np.argmax(d["a6"]))])
        w = (om > om[i1]) & (om <= 1.02)
        out[f"{name}_a6_ratio_near"] = float(d["a6"][w].max() / d["a6"][i1])
        out[f"{name}_a6_near_at"] = float(om[w][int(np.argmax(d["a6"][w]))])
        out[f"{name}_coup_max"] = float(d["coupling"].max())
        out[f"{name}_coup_at"] = float(om[int(np.argmax(d["coupling"]))])
    fw = data.fwd
    i1 = out["fwd_ref"]
    om = fw["omega"]
    # model sweet spot: forward tapping points above Omega(ref) whose coupling strength is
    # >= 3x its value at the reference point; the first run of them, bridging gaps of up to
    # 4 points (the orbit there is irregular and the coupling flickers from point to point)
    cand = (fw["contact"] > 0) & (om > om[i1]) & (fw["coupling"] >= 3 * fw["coupling"][i1])
    idx = np.flatnonzero(cand)
    if idx.size:
        run = np.split(idx, np.flatnonzero(np.diff(idx) > 5) + 1)[0]
        win = slice(int(run[0]), int(run[-1]) + 1)
        out["window"] = (float(om[run[0]]), float(om[run[-1]]))
        sl = fw["locked"][win] > 0
        out["win_dphi"] = (np.nanmin(fw["dphi"][win][sl]), np.nanmax(fw["dphi"][win][sl]),
                           np.nanmedian(fw["dphi"][win][sl])) if sl.any() else None
        out["win_a6_ratio"] = float(fw["a6"][win].max() / fw["a6"][i1])
        out["win_coup"] = float(fw["coupling"][win].max())
        out["win_indent"] = float(fw["indentation"][win].max())
        out["win_a6_at"] = float(om[win][int(np.argmax(fw["a6"][win]))])
    else:
        out["window"] = None
    # jumps in the tip amplitude (half-way between low and high branch, 0.5 L_ref)
    for name, d in (("fwd", data.fwd), ("rev", data.rev)):
        amp = 0.5 * (d["xmax"] - d["xmin"])
        up = np.flatnonzero(np.diff((amp > 0.5).astype(int)) != 0)
        out[f"{name}_jumps"] = [float(0.5 * (d["omega"][k] + d["omega"][k + 1])) for k in up]
    return out


def exp_window_values(d: dict, key: str, lo: float, hi: float, *, locked: bool = False):
    sel = (d["omega"] >= lo) & (d["omega"] <= hi)
    if locked:
        sel &= d["locked"] > 0
    v = d[key][sel]
    v = v[np.isfinite(v)]
    return (float(v.min()), float(v.max())) if v.size else None


# ---------------------------------------------------------------------------------- figures
def fig_main(d2: SweepData, d1: SweepData, summ: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(5, 2, figsize=(13, 15), sharex="col",
                             gridspec_kw={"width_ratios": [1.0, 1.3]})
    ref_f = d2.fwd["a6"][summ["fwd_ref"]]
    ref_r = d2.rev["a6"][summ["rev_ref"]]
    for col, xl in enumerate(((OMEGA_START, OMEGA_STOP), (OMEGA_START, 1.03))):
        ax = axes[:, col]
        for d, ls, lab, ref in ((d2.fwd, "-", "2-mode forward", ref_f),
                                (d2.rev, "--", "2-mode reverse", ref_r)):
            c = "C0" if ls == "-" else "C3"
            ax[0].plot(d["omega"], d["xmax"], ls, color=c, lw=1, label=lab)
            ax[0].plot(d["omega"], d["xmin"], ls, color=c, lw=1)
            ax[1].semilogy(d["omega"], d["a6"] / ref, ls, color=c, lw=1, label=lab)
            ax[1].set_ylim(1e-3, 40)
            ax[2].plot(d["omega"], d["coupling"], ls, color=c, lw=1, label=lab)
            lk = d["locked"] > 0
            ax[3].plot(d["omega"][lk], d["dphi"][lk], "o" if ls == "-" else "x", color=c,
                       ms=2.5, label=lab + " (locked points)")
            ax[4].plot(d["omega"], d["min_gap"], ls, color=c, lw=1, label=lab)
        ref1 = d1.fwd["a6"][nearest(d1.fwd, 1.0)]
        for d, ls in ((d1.fwd, "-"), (d1.rev, "--")):
            lab = "1-mode " + ("forward" if ls == "-" else "reverse")
            ax[0].plot(d["omega"], d["xmax"], ls, color="0.6", lw=0.8, label=lab)
            ax[0].plot(d["omega"], d["xmin"], ls, color="0.6", lw=0.8)
            if ls == "-":
                ax[1].semilogy(d["omega"], d["a6"] / ref1, ls, color="0.6", lw=0.8,
                               label="1-mode forward (own reference)")
        ax[4].axhline(A0, color="k", lw=0.6, ls=":")
        ax[4].text(xl[0], A0 + 0.01, " contact onset a0", fontsize=7)
        ax[1].axhline(7.0, color="k", lw=0.6, ls=":")
        ax[1].text(xl[0], 7.5, " experiment: x7", fontsize=7)
        for a in ax:
            a.set_xlim(*xl)
            a.axvspan(*EXP_SWEET, color="gold", alpha=0.25, lw=0)
            if summ.get("window"):
                a.axvspan(*summ["window"], color="C2", alpha=0.12, lw=0)
        for y, t in ((90, "exp. ~90 deg at f0"), (157.5, "exp. 152-163 deg sweet spot"),
                     (32, "exp. 32 deg at 167 kHz")):
            ax[3].axhline(y, color="k", lw=0.5, ls=":")
            if col == 1:
                ax[3].text(xl[1], y, t + " ", fontsize=7, ha="right", va="bottom")
        ax[-1].set_xlabel("drive frequency Omega = f / f0")
    axes[0, 0].set_ylabel("max / min tip deflection x [L_ref]")
    axes[1, 0].set_ylabel("6th harmonic |X6| / |X6(Omega~1)|")
    axes[2, 0].set_ylabel("coupling strength (share of mode 2)")
    axes[3, 0].set_ylabel("|phi2(6 Omega) - 6 phi1| [deg]")
    axes[4, 0].set_ylabel("minimum gap z_min [L_ref]")
    axes[3, 0].set_ylim(0, 180)
    axes[0, 1].legend(fontsize=7, loc="lower right")
    axes[1, 1].legend(fontsize=7, loc="upper right")
    axes[3, 1].legend(fontsize=7, loc="lower left")
    axes[0, 0].set_title("full sweep (Table 3.B.1 range)")
    axes[0, 1].set_title("zoom; gold: experiment's sweet spot 165-166 kHz, green: model's")
    fig.suptitle(f"2-mode VdW-DMT model, Table 3.B.1, C1 = {d2.c1:g}: "
                 "501 points x 50,000 samples per direction", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fig_orbits(d2: SweepData, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    oms = sorted(d2.orbits)
    fig, axes = plt.subplots(1, len(oms), figsize=(4.2 * len(oms), 3.4), sharey=True)
    for ax, om in zip(np.atleast_1d(axes), oms, strict=True):
        q, gap = d2.orbits[om]
        t = np.arange(q.shape[1]) * om / SAMPLES_PER_PERIOD
        ax.plot(t, q[0], lw=1, label="q1 (mode 1)")
        ax.plot(t, 10 * q[1], lw=1, label="10 x q2 (mode 2)")
        ax.plot(t, 1.0 - gap, lw=0.6, color="k", ls=":", label="1 - z (contact at 1 - a0)")
        ax.axhline(1.0 - A0, color="k", lw=0.5)
        ax.set_title(f"forward sweep, Omega = {om:.4f}", fontsize=9)
        ax.set_xlabel("drive periods")
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="lower left")
    np.atleast_1d(axes)[0].set_ylabel("[L_ref]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fig_c1(runs: list[SweepData], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(10, 10), sharex=True)
    cmap = plt.get_cmap("viridis")
    for j, r in enumerate(runs):
        c = cmap(j / max(1, len(runs) - 1))
        for d, ls in ((r.fwd, "-"), (r.rev, "--")):
            lab = f"C1 = {r.c1:g}" if ls == "-" else None
            axes[0].plot(d["omega"], 0.5 * (d["xmax"] - d["xmin"]), ls, color=c, lw=1, label=lab)
        i1 = nearest(r.fwd, 1.0)
        axes[1].semilogy(r.fwd["omega"], r.fwd["a6"] / r.fwd["a6"][i1], color=c, lw=1)
        axes[2].plot(r.fwd["omega"], r.fwd["coupling"], color=c, lw=1)
    axes[0].set_ylabel("tip amplitude (max - min)/2 [L_ref]\n(solid forward, dashed reverse)")
    axes[1].set_ylabel("forward: |X6| / |X6(Omega~1)|")
    axes[2].set_ylabel("forward: coupling strength")
    axes[2].set_xlabel("Omega")
    axes[0].legend(fontsize=8, ncol=2)
    for a in axes:
        a.set_xlim(OMEGA_START, 1.03)
        a.axvspan(*EXP_SWEET, color="gold", alpha=0.25, lw=0)
    fig.suptitle("2-mode model: effect of the van der Waals coefficient C1 (zoom 0.99-1.03)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------------------- doc
def write_doc_section(name: str, body: str) -> None:
    text = f"<!-- BEGIN {name} -->\n{body.strip()}\n<!-- END {name} -->"
    old = DOC.read_text() if DOC.exists() else "# Sweet spot\n"
    pat = re.compile(rf"<!-- BEGIN {re.escape(name)} -->.*?<!-- END {re.escape(name)} -->", re.S)
    new = pat.sub(lambda _m: text, old) if pat.search(old) else old.rstrip() + "\n\n" + text + "\n"
    DOC.write_text(new)
    print(text)


def f4(x) -> str:
    return "-" if x is None else (f"{x:.4f}" if isinstance(x, float) else
                                  "–".join(f"{v:.4f}" for v in x))


def rng(v, fmtstr="{:.0f}") -> str:
    if v is None:
        return "n/a"
    lo, hi = v[0], v[1]
    return fmtstr.format(lo) if abs(hi - lo) < 1e-12 else f"{fmtstr.format(lo)}–{fmtstr.format(hi)}"


def c1_row(r: SweepData) -> list:
    s = summarize(r)
    return [f"{r.c1:g}", f"{r.c1 / A0**2:.4g}", f4(s["fwd_tap"]), f4(s["rev_tap"]),
            ", ".join(f"{v:.4f}" for v in s["fwd_jumps"]) or "-",
            ", ".join(f"{v:.4f}" for v in s["rev_jumps"]) or "-",
            f"{s['fwd_a6_ratio_max']:.1f} @ {s['fwd_a6_ratio_at']:.4f}",
            f"{s['rev_a6_ratio_max']:.1f} @ {s['rev_a6_ratio_at']:.4f}",
            f"{s['fwd_coup_max']:.3f} @ {s['fwd_coup_at']:.4f}", f4(s["window"]),
            f"{np.nanmin(r.fwd['min_gap']):.3f}"]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--explore", action="store_true", help="also sweep the C1 grid")
    ap.add_argument("--c1", type=float, default=VDW_C1, help="C1 of the main run")
    ap.add_argument("--points", type=int, default=501)
    ap.add_argument("--samples", type=int, default=50_000)
    ap.add_argument("--robustness", action="store_true",
                    help="also rerun C1 in ROBUST_C1 with 2 RK4 steps per sample")
    ap.add_argument("--cache", action="store_true",
                    help=f"reuse sweeps cached in {CACHE} (keyed by the simulator source)")
    args = ap.parse_args(argv)
    FIG.mkdir(parents=True, exist_ok=True)
    info = C.machine_info()
    kw = {"points": args.points, "samples": args.samples, "cache": args.cache}
    t_all = time.time()
    orbit_at = (1.0, 1.0027, 1.008, 1.0145)
    runs: list[SweepData] = []
    one = None
    if args.explore:
        for c1 in sorted(set(C1_GRID) | {args.c1}):
            runs.append(run_sweep(2, c1, orbit_omegas=orbit_at, **kw))
            print(f"C1 = {c1:g}: {runs[-1].seconds:.0f} s", flush=True)
        fig_c1(runs, FIG / "sweet_spot_c1.png")
        one = run_sweep(1, args.c1, **kw)
        rows = [c1_row(r) for r in runs] + [["1-mode, " + c1_row(one)[0]] + c1_row(one)[1:]]
        write_doc_section("sweet_spot:c1", "\n".join([
            f"Generated by `python benchmarks/sweet_spot.py --explore` ({info['date']}; "
            f"{args.points} points x {args.samples:,} samples per direction, 2-mode model unless "
            "marked). Tapping range = lowest and highest Omega with any contact; jumps = where "
            "the tip amplitude (max - min)/2 crosses 0.5 L_ref; X6 ratio = largest 6th-harmonic "
            "amplitude of the tip deflection over its value at the point nearest Omega = 1 "
            "(same direction); window = model sweet spot (definition above).", "",
            C.md_table(["C1", "adhesion C1/a0^2 [k L_ref]", "forward tapping range",
                        "reverse tapping range", "forward jumps", "reverse jumps",
                        "forward X6 ratio max", "reverse X6 ratio max",
                        "forward coupling max", "model sweet-spot window",
                        "min gap (all points)"], rows),
            "", "![C1 exploration](figures/sweet_spot_c1.png)"]))
    if args.robustness:
        rrows = []
        for c1 in ROBUST_C1:
            for sub in (1, 2):
                r = run_sweep(2, c1, substeps=sub, **kw)
                sr = summarize(r)
                rrows.append([f"{c1:g}", sub, f4(sr["fwd_tap"]),
                              ", ".join(f"{v:.4f}" for v in sr["fwd_jumps"]) or "-",
                              f"{sr['fwd_a6_ratio_near']:.2f} @ {sr['fwd_a6_near_at']:.4f}",
                              f4(sr["window"]),
                              f"{sr['fwd_coup_max']:.3f} @ {sr['fwd_coup_at']:.4f}",
                              ", ".join(f"{v:.4f}" for v in sr["rev_jumps"]) or "-"])
                print(rrows[-1], flush=True)
        write_doc_section("sweet_spot:robustness", "\n".join([
            f"Generated by `python benchmarks/sweet_spot.py --robustness` ({info['date']}; "
            f"simulator source {SOURCE}). The same sweeps with one and with two RK4 steps per "
            "sample (errors ~2e-7 and ~1e-8 L_ref over 50 periods of a periodic 2-mode tapping "
            "orbit, docs/benchmarks.md). Forward direction unless marked.", "",
            C.md_table(["C1", "RK4 steps/sample", "forward tapping range", "forward jumps",
                        "forward X6 ratio in (1, 1.02]", "model window", "forward coupling max",
                        "reverse jumps"], rrows)]))
    d2 = next((r for r in runs if r.c1 == args.c1), None)
    if d2 is None:
        d2 = run_sweep(2, args.c1, orbit_omegas=orbit_at, **kw)
    d1 = one if one is not None else run_sweep(1, args.c1, **kw)
    s = summarize(d2)
    s1 = summarize(d1)
    fig_main(d2, d1, s, FIG / "sweet_spot.png")
    fig_orbits(d2, FIG / "sweet_spot_orbits.png")
    fw, rv = d2.fwd, d2.rev
    i1 = s["fwd_ref"]
    sweet_d = exp_window_values(fw, "dphi", *EXP_SWEET, locked=True)
    sweet_a6 = exp_window_values(fw, "a6", *EXP_SWEET)
    sweet_c = exp_window_values(fw, "coupling", *EXP_SWEET)
    k_b = nearest(fw, EXP_BEYOND)
    k_br = nearest(rv, EXP_BEYOND)
    rows = [
        ["softening (leftward bend at low amplitude)", "yes (ch. 3 FRC)",
         f"reverse sweep stays on the upper branch down to Omega = "
         f"{s['rev_jumps'][0] if s['rev_jumps'] else float('nan'):.4f} (C1 = 0: see C1 table)",
         "qualitative"],
        ["hardening + jump (forward)", "hardening, then a jump (ch. 3 FRC)",
         f"tapping {f4(s['fwd_tap'])}, amplitude jumps at "
         + ", ".join(f"{v:.4f}" for v in s["fwd_jumps"]), "qualitative"],
        ["sweet-spot location", f"165–166 kHz = Omega {EXP_SWEET[0]:.4f}–{EXP_SWEET[1]:.4f}",
         f"model window (definition above): {f4(s['window'])}"
         + (f", largest X6 at {s['win_a6_at']:.4f}" if s.get("window") else ""), "-"],
        ["6th harmonic rise (vs f0)", "x7",
         f"forward: x{s['fwd_a6_ratio_max']:.1f} (max at {s['fwd_a6_ratio_at']:.4f}); inside "
         f"165–166 kHz: x{rng(sweet_a6 and tuple(v / fw['a6'][i1] for v in sweet_a6), '{:.1f}')}; "
         f"reverse: x{s['rev_a6_ratio_max']:.1f} (at {s['rev_a6_ratio_at']:.4f})",
         "reference = point nearest Omega = 1"],
        ["17th harmonic rise", "x16", "not representable (needs mode 3)", "-"],
        ["coupling strength (share of mode 2)", "rises in the sweet spot",
         f"forward: {fw['coupling'][i1]:.4f} at Omega = {fw['omega'][i1]:.4f}; "
         f"{rng(sweet_c, '{:.4f}')} inside 165–166 kHz; max {s['fwd_coup_max']:.3f} at "
         f"{s['fwd_coup_at']:.4f}", "-"],
        ["mode phase difference at f0", "~90 deg",
         f"{fw['dphi'][i1]:.0f} deg (forward, Omega = {fw['omega'][i1]:.4f}"
         + ("" if fw["locked"][i1] else ", not locked") + ")", "definition above"],
        ["mode phase difference in the sweet spot", "152–163 deg",
         f"{rng(sweet_d)} deg (forward, locked points in 165–166 kHz); "
         + (f"{rng(s['win_dphi'][:2])} deg, median {s['win_dphi'][2]:.0f}, in the model "
            "window" if s.get("win_dphi") else ""), "-"],
        ["mode phase difference beyond (167 kHz)", "32 deg",
         f"forward {fw['dphi'][k_b]:.0f} deg" + ("" if fw["locked"][k_b] else " (not locked)")
         + f", reverse {rv['dphi'][k_br]:.0f} deg" + ("" if rv["locked"][k_br] else
                                                       " (not locked)")
         + f" at Omega = {fw['omega'][k_b]:.4f}", "-"],
        ["minimum gap / indentation",
         "reduced in the sweet spot (deflection minima curve up, 165-166 kHz; ch. 3 Fig. 3.2a "
         "inset, App. 3.C), no number",
         f"forward at Omega~1: z_min = {fw['min_gap'][i1]:.3f} (indentation "
         f"{fw['indentation'][i1]:.3f}); max indentation in the model window "
         f"{s.get('win_indent', float('nan')):.3f}; smallest z_min "
         f"{np.min(fw['min_gap']):.3f}", "units of the rest gap (100 nm)"],
        ["1-mode model, same parameters", "misses the sweet spot (ch. 3)",
         f"forward X6 ratio in (1, 1.02]: x{s1['fwd_a6_ratio_near']:.1f} (2 modes: "
         f"x{s['fwd_a6_ratio_near']:.1f}); over the whole range x{s1['fwd_a6_ratio_max']:.1f} at "
         f"{s1['fwd_a6_ratio_at']:.4f}, where the hardening branch indents deepest "
         f"(z_min {np.min(d1.fwd['min_gap']):.3f}); max X6/X1 "
         f"{np.max(d1.fwd['a6'] / d1.fwd['a1']):.4f} (2 modes: "
         f"{np.max(fw['a6'] / fw['a1']):.3f}); "
         f"tapping {f4(s1['fwd_tap'])}; jumps "
         + (", ".join(f"{v:.4f}" for v in s1["fwd_jumps"]) or "none"), "-"],
    ]
    body = "\n".join([
        f"Generated by `python benchmarks/sweet_spot.py{' --explore' if args.explore else ''}` "
        f"({info['date']}, C1 = {args.c1:g}, {args.points} points x {args.samples:,} samples "
        f"per direction; wall time: 2-mode {d2.seconds:.0f} s, 1-mode {d1.seconds:.0f} s "
        f"for both directions incl. feature extraction; total {time.time() - t_all:.0f} s).", "",
        C.md_table(["observable", "dissertation (NCLR on Si, measured)", "this model",
                    "note"], rows),
        "", "![sweet spot](figures/sweet_spot.png)", "",
        "Orbits in the forward sweep (last two periods of the point; mode 2 magnified x10):", "",
        "![orbits](figures/sweet_spot_orbits.png)",
    ])
    write_doc_section("sweet_spot:main", body)
    # per-point table of the forward sweep around the sweet spot (every 2nd point)
    sel = np.flatnonzero((fw["omega"] >= 0.995) & (fw["omega"] <= 1.02))[::2]
    prow = [[f"{fw['omega'][k]:.4f}", f"{fw['xmax'][k]:.3f}", f"{fw['xmin'][k]:.3f}",
             f"{fw['min_gap'][k]:.3f}", f"{fw['contact'][k]:.3f}", f"{fw['a1'][k]:.3f}",
             f"{fw['a6'][k]:.4f}", f"{fw['a6'][k] / fw['a6'][i1]:.2f}",
             f"{fw['coupling'][k]:.4f}",
             f"{fw['dphi'][k]:.0f}" + ("" if fw["locked"][k] else " (unlocked)")]
            for k in sel]
    write_doc_section("sweet_spot:table", "\n".join([
        "Forward sweep, every second point in 0.995–1.02 (C1 = " f"{args.c1:g}):", "",
        C.md_table(["Omega", "x max", "x min", "z min", "contact fraction", "X1 amp.", "X6 amp.",
                    "X6 / X6(1)", "coupling", "dphi [deg]"], prow)]))


if __name__ == "__main__":
    main()
