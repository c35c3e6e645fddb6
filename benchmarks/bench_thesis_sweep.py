"""Wall time of the thesis-scale frequency sweep, and the naive solve_ivp baseline.

Thesis sweep (dissertation ch. 3/6): 501 drive frequencies ``Omega = 0.990149 ... 1.1327``,
50,000 samples per frequency at 1,500 samples per free period (``dt = 2 pi / 1500``), the
2-mode Table 3.B.1 system of ``_systems.py``, ``simulator.Sweep`` with its default settling
(2.5 Q1 periods at the first frequency) and the automatic RK4 (one step per sample here).

Measured: forward only, and forward + reverse as one batch of two trajectories (two numba
threads on the two cores), each (a) into memory with ``Sweep.run`` and (b) streamed row by row
to HDF5 with ``afmlearn.io.TraceWriter`` (SI units: k = 22.68 N/m, f0 = 164.52 kHz,
L_ref = 100 nm, the NCLR set-up of ch. 3; one file per direction, written to a temporary
folder and deleted). Also: the integrator alone on the same schedule (``RK4.run`` per point,
no labels, no result arrays), to separate the kernel from the scenario's overhead.

Baseline (the issue's "naive" sweep: 500 frequencies x 300 periods with solve_ivp, ~3-4 min
on one core): a reduced run of ``--baseline-freqs`` frequencies x ``--baseline-periods``
periods, each continuing from the previous state, samples at 1,500 per period via ``t_eval``,
lean scalar right-hand side (``_lean_ivp.py``), rtol 1e-8 / atol 1e-10, on one core. Its
cost per simulated period is EXTRAPOLATED linearly to the full sizes.

Run: ``python benchmarks/bench_thesis_sweep.py [--no-h5] [--no-baseline] [--baseline-freqs 20]
[--baseline-periods 30]``
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import _common as C  # first: puts the repository root on sys.path
import numpy as np
from _lean_ivp import lean_solve_ivp
from _systems import OMEGA_START, OMEGA_STOP, SAMPLES_PER_PERIOD, VDW_C1, system

from simulator import RK4, Scales, State, Sweep
from simulator.scenarios.base import auto_settle_periods

N_POINTS = 501
N_SAMPLES = 50_000
SCALES = Scales(spring_constant=22.68, resonance_frequency=164.52e3, length=100e-9)


def make_sweep(direction: str) -> Sweep:
    return Sweep(omega_start=OMEGA_START, omega_stop=OMEGA_STOP, n_points=N_POINTS,
                 samples_per_point=N_SAMPLES, samples_per_period=SAMPLES_PER_PERIOD,
                 direction=direction)


def in_memory(direction: str) -> tuple[float, int]:
    sw = make_sweep(direction)
    s = system(2)
    t0 = time.perf_counter()
    res = sw.run(s)
    t = time.perf_counter() - t0
    nbytes = sum(a.nbytes for a in (res.q, res.force, res.gap, res.rest_gap, res.contact,
                                    res.phase))
    del res
    return t, nbytes


def streamed(direction: str, folder: Path) -> tuple[float, int]:
    from afmlearn.io import TraceWriter

    sw = make_sweep(direction)
    s = system(2)
    ell, fu, en = SCALES.length, SCALES.force, SCALES.energy
    f0 = SCALES.resonance_frequency
    common = dict(n_samples=N_SAMPLES, n_points=N_POINTS, n_modes=2,
                  model=s.to_dict(), sample_rate_hz=f0 * SAMPLES_PER_PERIOD,
                  spring_constant_n_per_m=SCALES.spring_constant,
                  quality_factor=float(s.cantilever.quality_factors[0]),
                  resonance_frequency_hz=f0, gap_m=sw.gap * ell, excitation="base",
                  dither_amplitude_m=s.excitation.amplitude * ell)
    t0 = time.perf_counter()
    writers = {}
    try:
        for d in sw.directions:
            om = sw.omegas if d == "forward" else sw.omegas[::-1]
            writers[d] = TraceWriter(folder / f"sweep_{d}.h5", drive_frequency_hz=om * f0,
                                     **common).__enter__()
        for p in sw.iter_points(s):
            lab = p.labels
            k = p.row % N_POINTS
            q = p.q
            writers[p.direction].write_row(
                k, q.sum(axis=0) * ell, force_n=p.force * fu, modal_m=q * ell,
                scalars={"dissipated_energy_j": lab["dissipated_energy"] * en,
                         "amplitude_m": lab["amplitude"] * ell,
                         "min_gap_m": lab["min_gap"] * ell,
                         "contact_fraction": lab["contact_fraction"],
                         "coupling_strength": lab["coupling_strength"]})
    except BaseException as e:
        for w in writers.values():
            w.__exit__(type(e), e, None)
        raise
    for w in writers.values():
        w.__exit__(None, None, None)
    t = time.perf_counter() - t0
    size = sum(f.stat().st_size for f in folder.glob("sweep_*.h5"))
    for f in folder.glob("sweep_*.h5"):
        f.unlink()
    return t, size


def integrator_only(direction: str) -> float:
    """The sweep's integration schedule with ``RK4.run`` only (settle + every point)."""
    sw = make_sweep(direction)
    s = system(2)
    w = sw.omegas
    sched = np.stack([w if d == "forward" else w[::-1] for d in sw.directions])
    rk = RK4()
    t0 = time.perf_counter()
    st = State.free_orbit(s, omega=sched[:, 0])
    n_set = int(math.ceil(auto_settle_periods(s) * 2 * math.pi / (sched[:, 0].min() * sw.dt)))
    while n_set > 0:
        m = min(n_set, 200_000)
        st = rk.run(s, st, omega=sched[:, 0], n_samples=m, dt=sw.dt).end
        n_set -= m
    for k in range(N_POINTS):
        st = rk.run(s, st, omega=sched[:, k], n_samples=N_SAMPLES, dt=sw.dt).end
    return time.perf_counter() - t0


def baseline(n_modes: int, method: str, n_freq: int, periods: float) -> dict:
    """Reduced naive solve_ivp sweep on one core; returns seconds per simulated period."""
    s = system(n_modes)
    oms = np.linspace(OMEGA_START, OMEGA_STOP, n_freq)
    st = State.free_orbit(s, omega=[oms[0]])
    dt = 2 * math.pi / SAMPLES_PER_PERIOD
    t0 = time.perf_counter()
    total_periods = 0.0
    for om in oms:
        n = int(round(periods * SAMPLES_PER_PERIOD / om))
        _, st = lean_solve_ivp(s, st, omega=float(om), n_samples=n, dt=dt, method=method,
                               rtol=1e-8, atol=1e-10)
        total_periods += n * dt * om / (2 * math.pi)
    t = time.perf_counter() - t0
    return {"time": t, "periods": total_periods, "per_period": t / total_periods}


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-h5", action="store_true", help="skip the HDF5 streaming runs")
    ap.add_argument("--no-baseline", action="store_true", help="skip the solve_ivp baseline")
    ap.add_argument("--baseline-freqs", type=int, default=20)
    ap.add_argument("--baseline-periods", type=float, default=30.0)
    ap.add_argument("--points", type=int, default=501, help="smoke tests only (thesis: 501)")
    ap.add_argument("--samples", type=int, default=50_000,
                    help="smoke tests only (thesis: 50,000)")
    C.add_doc_flag(ap)
    args = ap.parse_args(argv)
    global N_POINTS, N_SAMPLES
    N_POINTS, N_SAMPLES = args.points, args.samples
    info = C.machine_info()
    s = system(2)
    # warm-up (compile / cache load) outside the timings
    RK4().run(s, State.free_orbit(s, omega=[1.0, 1.0]), omega=1.0, n_samples=100,
              dt=2 * math.pi / SAMPLES_PER_PERIOD)
    settle_samples = auto_settle_periods(s) * SAMPLES_PER_PERIOD / OMEGA_START
    rows = []
    rk_rate = {}
    for direction in ("forward", "both"):
        ntraj = 2 if direction == "both" else 1
        t_int = integrator_only(direction)
        steps = ntraj * (N_POINTS * N_SAMPLES + settle_samples)
        rk_rate[direction] = t_int / (ntraj * N_POINTS * N_SAMPLES)
        rows.append([direction, "integrator only (RK4.run per point, no labels)",
                     f"**{t_int:.1f}**", f"{steps / t_int / 1e6:.2f}", "-"])
        print(rows[-1], flush=True)
        t_mem, nbytes = in_memory(direction)
        rows.append([direction, "Sweep.run, in memory", f"**{t_mem:.1f}**",
                     f"{steps / t_mem / 1e6:.2f}", f"{nbytes / 1e9:.2f} GB in RAM"])
        print(rows[-1], flush=True)
        if not args.no_h5:
            try:
                import afmlearn.io  # noqa: F401
            except ImportError as e:  # pragma: no cover
                rows.append([direction, f"HDF5 streaming unavailable: {e}", "-", "-", "-"])
            else:
                with tempfile.TemporaryDirectory(dir="/tmp") as tmp:
                    t_h5, size = streamed(direction, Path(tmp))
                rows.append([direction, "Sweep.iter_points -> TraceWriter (HDF5, SI)",
                             f"**{t_h5:.1f}**", f"{steps / t_h5 / 1e6:.2f}",
                             f"{size / 1e9:.2f} GB on disk"])
                print(rows[-1], flush=True)
    body = [
        f"2-mode Table 3.B.1 system (C1 = {VDW_C1:g}), {N_POINTS} frequencies x {N_SAMPLES:,} "
        f"samples at {SAMPLES_PER_PERIOD} samples per period (`dt = 2 pi / 1500`, one RK4 "
        f"step per sample), plus {settle_samples:,.0f} settling samples (2.5 Q1 periods) at "
        "the first frequency. `both` = forward and reverse sweeps as one batch of two "
        "trajectories (two threads). Goal: <= 10 s. Steps/s counts all integrated samples of "
        "all trajectories, settling included.", "",
        C.md_table(["direction", "what", "wall [s]", "M steps/s", "memory / output"], rows),
    ]
    if not args.no_baseline:
        brow = []
        thesis_periods = N_POINTS * N_SAMPLES / SAMPLES_PER_PERIOD * float(
            np.mean(np.linspace(OMEGA_START, OMEGA_STOP, N_POINTS)))
        issue_periods = 500 * 300
        for m in (1, 2):
            for meth in ("LSODA", "DOP853"):
                r = baseline(m, meth, args.baseline_freqs, args.baseline_periods)
                brow.append([f"{m}-mode", meth, f"{r['time']:.1f}",
                             f"{r['periods']:.0f}", f"{1e3 * r['per_period']:.2f}",
                             f"{r['per_period'] * issue_periods / 60:.1f} min",
                             f"{r['per_period'] * thesis_periods / 60:.1f} min",
                             f"{r['per_period'] * 2 * thesis_periods / 60:.1f} min"])
                print(brow[-1], flush=True)
        rk_issue = rk_rate["forward"] * issue_periods * SAMPLES_PER_PERIOD
        body += [
            "", f"Naive solve_ivp sweep baseline (lean scalar RHS, rtol 1e-8, atol 1e-10, "
            f"samples at 1,500 per period via `t_eval`, one core): measured on "
            f"{args.baseline_freqs} frequencies x {args.baseline_periods:g} periods, then "
            "**extrapolated** linearly in the number of simulated periods to the issue's "
            f"500 x 300 periods and to the thesis sweep ({thesis_periods:,.0f} periods per "
            "direction).", "",
            C.md_table(["model", "method", "measured wall [s]", "measured periods",
                        "ms / period", "500 x 300 periods (extrapolated)",
                        "thesis sweep, forward (extrapolated)",
                        "thesis sweep, forward + reverse, 1 core (extrapolated)"], brow),
            "", "For comparison, RK4 at the integrator-only rate of the forward run above "
            f"would take {rk_issue:.0f} s for the issue's 500 x 300 periods at 1,500 samples "
            "per period (also an extrapolation).",
        ]
    return C.write_section("bench_thesis_sweep", "Thesis-scale sweep (`bench_thesis_sweep.py`)",
                           "\n".join(body), info, write=not args.no_doc)


if __name__ == "__main__":
    t0 = time.time()
    main()
    print(f"(total {time.time() - t0:.0f} s)")
