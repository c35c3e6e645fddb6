"""QRNN vs LSTM vs GRU speed on this CPU: training throughput and inference latency per period.

Networks of equal hidden size (64, 128 and 256) and 2 layers (`afmlearn.qrnn.networks`), input one
period of ``P`` samples (default 64, the data module's ``samples_per_period``) with 2 features
(deflection and a constant drive-frequency channel), a linear read-out per time step.

- Training throughput: samples/s of one step forward + backward + Adam on a batch of 64.
- Inference latency: wall time of one period, batch 1, ``eval()`` + ``torch.inference_mode``.
- The scan alone (fo-pooling, one period): forward + backward at batch 64, forward at batch 1,
  for the default choice, recursive doubling and each chunk length vs the readable reference
  loop, to choose the default (`LOOP_ABOVE`).

torch runs with 2 intra-op threads. Models are timed in interleaved rounds and the best round
is kept, so a load spike from other processes hits all models alike and is mostly filtered out.
The whole measurement is repeated ``--repeats`` times (default 3); the tables give the median
and the range (min - max) over the repetitions, and the load average before and after.

Variants (issue 15): the shipped QRNN (2 layers, window 2, fo-pooling), the same with window 1 in
the upper layer (``upper_window=1``, as Merity et al.'s awd-lstm-lm QRNN: half the arithmetic
of layer 2), f-pooling, and with ``--compile`` the shipped QRNN under ``torch.compile``
(inductor, C++ on CPU; compile time reported).

``--clock cpu`` times CPU time of the process instead of elapsed time (section
``qrnn_speed_cpu``): on the shared machine other processes stretch elapsed times by a varying
factor, CPU time much less; with ``--threads 1`` it is the cost of a step on one core.

Run: ``nice -n 10 python benchmarks/bench_qrnn_speed.py [--quick] [--repeats 3] [--compile]
[--threads 2] [--clock wall|cpu] [--no-doc]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import _common as C  # first: puts the repository root on sys.path
import torch

from afmlearn.qrnn.layer import FOPooling, FPooling
from afmlearn.qrnn.networks import AbstractSequenceNet, GRUNet, LSTMNet, QRNNNet
from afmlearn.qrnn.scan import ChunkedScan, DoublingScan, fo_pool, fo_pool_reference, prefix_scan

BATCH = 64
N_FEATURES = 2
AUTO = "QRNN window 2 / 2 (issue-4 shape), fo, default scan"
UPPER1 = "QRNN window 2 / 1 (shipped), fo, default scan"
COMPILED = "QRNN window 2 / 2, torch.compile"


#: the clock of the ratios: "wall" (time.perf_counter) or "cpu" (time.process_time: CPU time
#: of this process, all its threads; far less disturbed by other processes on a shared machine)
CLOCK = {"wall": time.perf_counter, "cpu": time.process_time}
_clock = CLOCK["wall"]


def _best_interleaved(fns: dict[str, Callable[[], object]], *, rounds: int,
                      inner: int) -> dict[str, float]:
    """Best time [s] per call of every function, timed in interleaved rounds."""
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(rounds):
        for name, fn in fns.items():
            t0 = _clock()
            for _ in range(inner):
                fn()
            best[name] = min(best[name], (_clock() - t0) / inner)
    return best


def _models(hidden: int, chunks: list[int], *, compiled: bool = False
            ) -> dict[str, AbstractSequenceNet]:
    torch.manual_seed(0)
    out: dict[str, AbstractSequenceNet] = {
        "LSTM": LSTMNet(N_FEATURES, hidden, num_layers=2),
        "GRU": GRUNet(N_FEATURES, hidden, num_layers=2),
    }
    out[AUTO] = QRNNNet(N_FEATURES, hidden, num_layers=2, window=2)
    out[UPPER1] = QRNNNet(N_FEATURES, hidden, num_layers=2, window=2, upper_window=1)
    if compiled:
        out[COMPILED] = torch.compile(QRNNNet(N_FEATURES, hidden, num_layers=2, window=2))
    out["QRNN f-pooling (default scan)"] = QRNNNet(N_FEATURES, hidden, num_layers=2, window=2,
                                                   pooling=FPooling())
    out["QRNN doubling"] = QRNNNet(N_FEATURES, hidden, num_layers=2, window=2,
                                   pooling=FOPooling(scan=DoublingScan()))
    for ch in chunks:
        out[f"QRNN chunk {ch}"] = QRNNNet(N_FEATURES, hidden, num_layers=2, window=2,
                                          pooling=FOPooling(scan=ChunkedScan(chunk=ch)))
    return out


def _train_step(net: AbstractSequenceNet, x: torch.Tensor,
                y: torch.Tensor) -> Callable[[], None]:
    head = torch.nn.Linear(net.hidden_size, 1)
    opt = torch.optim.Adam([*net.parameters(), *head.parameters()], lr=1e-3)

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        loss = (head(net(x)) - y).square().mean()
        loss.backward()
        opt.step()

    step()  # warm-up (allocations, Adam state)
    return step


def _infer(net: AbstractSequenceNet, x1: torch.Tensor) -> Callable[[], None]:
    net.eval()

    def run() -> None:
        with torch.inference_mode():
            net(x1)

    run()
    return run


def bench_networks(hidden: int, period: int, chunks: list[int], *, rounds: int,
                   compiled: bool = False) -> list[dict]:
    models = _models(hidden, chunks, compiled=compiled)
    g = torch.Generator().manual_seed(1)
    x = torch.randn(BATCH, period, N_FEATURES, generator=g)
    y = torch.randn(BATCH, period, 1, generator=g)
    x1 = torch.randn(1, period, N_FEATURES, generator=g)
    steps, compile_s = {}, float("nan")
    for k, m in models.items():
        t0 = time.perf_counter()
        steps[k] = _train_step(m, x, y)
        if k == COMPILED:
            compile_s = time.perf_counter() - t0
    train = _best_interleaved(steps, rounds=rounds, inner=1)
    infer = _best_interleaved({k: _infer(m, x1) for k, m in models.items()},
                              rounds=rounds, inner=10)
    return [{"hidden": hidden, "model": k, "train_s": train[k], "infer_s": infer[k],
             "ratio": train["LSTM"] / train[k], "compile_s": compile_s} for k in models]


def bench_scan(hidden: int, period: int, chunks: list[int], *, rounds: int) -> list[list]:
    """Scan alone: forward + backward at batch 64, forward (inference) at batch 1 [s]."""
    rows = []
    for batch, grad in ((BATCH, True), (1, False)):
        g = torch.Generator().manual_seed(2)
        f = torch.rand(batch, period, hidden, generator=g).requires_grad_(grad)
        z = torch.randn(batch, period, hidden, generator=g).requires_grad_(grad)

        def make(fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], f: torch.Tensor = f,
                 z: torch.Tensor = z, grad: bool = grad) -> Callable[[], None]:
            def run() -> None:
                if grad:
                    fn(f, z).sum().backward()
                else:
                    with torch.inference_mode():
                        fn(f, z)
            run()
            return run

        fns = {"loop": make(fo_pool_reference), "auto": make(fo_pool),
               "doubling": make(lambda a, b: prefix_scan(a, (1.0 - a) * b))}
        for ch in chunks:
            fns[str(ch)] = make(lambda a, b, ch=ch: fo_pool(a, b, chunk=ch))
        t = _best_interleaved(fns, rounds=rounds, inner=3)
        rows.append([hidden, batch, "fwd + bwd" if grad else "fwd"]
                    + [C.fmt(1e3 * t[k]) for k in ("loop", "auto", "doubling", *map(str, chunks))])
    return rows


def _spread(values: list[float], fmt: Callable[[float], str] = C.fmt) -> str:
    """``median (min - max)`` of repeated measurements."""
    if len(values) == 1:
        return fmt(values[0])
    return f"{fmt(statistics.median(values))} ({fmt(min(values))} - {fmt(max(values))})"


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer rounds, hidden 64 only")
    ap.add_argument("--period", type=int, default=64, help="samples per period P")
    ap.add_argument("--chunks", default="1,8", help="chunk lengths of the QRNN scan")
    ap.add_argument("--hiddens", default="64,128",
                    help="hidden sizes (64: the size of conf/model/qrnn.yaml)")
    ap.add_argument("--repeats", type=int, default=3, help="repetitions of the whole run")
    ap.add_argument("--compile", action="store_true", help="also time torch.compile")
    ap.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    ap.add_argument("--clock", choices=sorted(CLOCK), default="wall",
                    help="wall: elapsed time; cpu: CPU time of the process (robust to load)")
    C.add_doc_flag(ap)
    args = ap.parse_args(argv)
    global _clock
    _clock = CLOCK[args.clock]
    torch.set_num_threads(args.threads)
    info = C.machine_info()
    info["torch"] = f"{torch.__version__} (intra-op threads: {torch.get_num_threads()})"
    info["niceness"] = str(os.nice(0))
    chunks = sorted({int(c) for c in args.chunks.split(",")})
    hiddens = [64] if args.quick else [int(h) for h in args.hiddens.split(",")]
    rounds = 3 if args.quick else 8
    loads = [os.getloadavg()[0]]

    runs: list[list[dict]] = []
    scan_rows = []
    for rep in range(args.repeats):
        rows = []
        for hidden in hiddens:
            rows += bench_networks(hidden, args.period, chunks, rounds=rounds,
                                   compiled=args.compile)
            if rep == 0:
                scan_rows += bench_scan(hidden, args.period, chunks, rounds=rounds)
        runs.append(rows)
        loads.append(os.getloadavg()[0])
    keys = [(r["hidden"], r["model"]) for r in runs[0]]

    def values(key: tuple[int, str], field: str) -> list[float]:
        return [next(r[field] for r in run if (r["hidden"], r["model"]) == key) for run in runs]

    table = C.md_table(
        ["hidden", "model", "train samples/s", "QRNN/LSTM train throughput",
         "inference ms/period"],
        [[h, m, _spread([BATCH / v for v in values((h, m), "train_s")]),
          _spread(values((h, m), "ratio")),
          _spread([1e3 * v for v in values((h, m), "infer_s")])] for h, m in keys])
    scan_table = C.md_table(["hidden", "batch", "pass", "reference loop ms", "auto ms",
                             "doubling ms"]
                            + [f"chunk {c} ms" for c in chunks], scan_rows)
    verdict = []
    for hidden in hiddens:
        for name in (AUTO, UPPER1, *([COMPILED] if args.compile else [])):
            ratio = statistics.median(values((hidden, name), "ratio"))
            inf = statistics.median(values((hidden, name), "infer_s"))
            verdict.append(
                f"- hidden {hidden}, {name}: QRNN/LSTM training throughput {C.fmt(ratio)}x "
                f"(median of {args.repeats}; goal >= 2: {'met' if ratio >= 2 else 'NOT met'}); "
                f"inference {C.fmt(1e3 * inf)} ms per period "
                f"(goal <= 1 ms: {'met' if inf <= 1e-3 else 'NOT met'})")
    if args.compile:
        comp = [v for run in runs for r in run if r["model"] == COMPILED
                for v in [r["compile_s"]]]
        verdict.append(f"- torch.compile: first step (compilation) {_spread(comp)} s")
    clock = ("elapsed (wall-clock) time" if args.clock == "wall" else
             "CPU time of the process (`time.process_time`, all its threads: what a step costs, "
             "not how long it waited for a core)")
    body = f"""Clock: {clock}; {args.threads} torch thread(s).

Two-layer networks of equal hidden size, batch {BATCH}, one period of
P = {args.period} samples with {N_FEATURES} input features, forward + backward + Adam per
training step; inference is batch 1, one period. QRNN: fo-pooling; its scan
(`afmlearn/qrnn/scan.py`) by default picks per call: the plain time-major loop for wide steps
(batch x hidden >= 4096), else recursive doubling (log2 P whole-sequence steps). Best of {rounds}
interleaved rounds per repetition; {args.repeats} repetitions, median (min - max). Load average
(1 min) before / after each repetition: {' / '.join(f'{v:.1f}' for v in loads)} on
{os.cpu_count()} cores (the machine is shared; the process ran at niceness {os.nice(0)}).

Arithmetic bound: per sample and time step a 2-layer LSTM multiplies about 12 H^2 (4H x H
recurrent in layer 1, 4H x 2H in layer 2), a window-2 fo-pooling QRNN about 6 H^2 (3 gates x
2H x H in layer 2; layer 1 sees only {N_FEATURES} features), with window 1 in layer 2 about
3 H^2, f-pooling 4 H^2. When both run their matrix products at the same efficiency the
window-2 fo-QRNN/LSTM ratio therefore tends to ~2 from below (its gain is the parallel time
axis, not fewer multiplications); window 2 / upper 1 to ~4, f-pooling to ~3.

{table}

Scan alone (fo-pooling, P = {args.period}; training: forward + backward at batch {BATCH};
inference: forward at batch 1; first repetition):

{scan_table}

{chr(10).join(verdict)}
"""
    name = "qrnn_speed" if args.clock == "wall" else "qrnn_speed_cpu"
    title = "QRNN vs LSTM vs GRU speed (CPU)" + ("" if args.clock == "wall" else
                                                 ", CPU-time clock")
    return C.write_section(name, title, body, info, write=not args.no_doc)


if __name__ == "__main__":
    main()
