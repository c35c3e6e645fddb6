"""Figure of a free-oscillation diagnosis (matplotlib, Agg canvas, PNG written atomically).

`plot_free_diagnosis`
    (a) the fundamental's instantaneous frequency and amplitude versus time, the held-out span
    shaded; (b) ``|X_n| / |X_1|`` of harmonics 2 and 3 per block against the amplitude,
    with the slopes an ``A^n`` law (detector map, gap-modulated force) and a fixed-amplitude
    drive predict; (c) one period of the held-out record minus its fundamental, phase-averaged,
    with the named model's prediction; (d) the held-out gain of every candidate cause (hatched:
    excluded by the evidence whatever its gain).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from afmlearn.freeosc.diagnose import FreeOscillationDiagnosis
from afmlearn.plots.trace import _out_dir, _save
from afmlearn.preprocess.harmonics import phase_average

__all__ = ["plot_free_diagnosis"]


def plot_free_diagnosis(diagnosis: FreeOscillationDiagnosis, y: NDArray[np.float64],
                        prediction: NDArray[np.float64] | None,
                        out_dir: str | os.PathLike[str], *, unit: str = "record units",
                        name: str = "free_diagnosis.png") -> Path:
    """Draw ``diagnosis`` of record ``y`` (shape (n,)); ``prediction`` (shape (n,)) is the
    named model's prediction of the whole record (None: not drawn). Returns the PNG path."""
    d, tr = diagnosis.demod, diagnosis.track
    fig = Figure(figsize=(9.0, 6.6))
    FigureCanvasAgg(fig)
    (ax_f, ax_h), (ax_w, ax_g) = fig.subplots(2, 2)
    valid = np.flatnonzero(d.valid)
    step = max(1, valid.size // 4000)
    sel = valid[::step]
    t_ms = d.time_s[sel] * 1e3
    ax_f.plot(t_ms, d.frequency_hz[sel] - d.carrier_hz, lw=0.6, color="C0")
    ax_f.set_xlabel("time [ms]")
    ax_f.set_ylabel(f"f - {d.carrier_hz:.1f} Hz [Hz]", color="C0")
    ax_f.axvspan(diagnosis.split_time_s * 1e3, t_ms[-1], color="0.9", zorder=0)
    ax_a = ax_f.twinx()
    ax_a.plot(t_ms, d.amplitude[sel], lw=0.8, color="C3")
    ax_a.set_ylabel(f"amplitude A [{unit}]", color="C3")
    ax_f.set_title("(a) fundamental (held-out span shaded)", fontsize=9)

    amp = tr.amplitude
    for n, col in ((2, "C0"), (3, "C1")):
        rel = tr.relative[:, n - 1]
        ax_h.scatter(amp, rel / rel.mean(), s=10, color=col, label=f"|X{n}|/|X1|, n = {n}")
        ref = np.linspace(amp.min(), amp.max(), 2)
        ax_h.plot(ref, (ref / amp.mean()) ** (n - 1), "-", color=col, lw=0.8,
                  label=f"A^{n} law (detector / gap force)")
    ax_h.plot(ref, (ref / amp.mean()) ** -1, "k--", lw=0.8, label="fixed drive (A^0)")
    ax_h.set_xlabel(f"block amplitude |X1| [{unit}]")
    ax_h.set_ylabel("relative harmonic / its mean")
    ax_h.legend(fontsize=6)
    ax_h.set_title("(b) harmonics vs amplitude, per block", fontsize=9)

    test = valid[d.time_s[valid] >= diagnosis.split_time_s]
    resid = y[test] - d.fundamental()[test]
    centres, mean, _ = phase_average(d.phase[test], resid, 1.0, 38)
    ax_w.plot(centres, mean, "o", ms=3, color="0.3", label="measured - fundamental")
    if prediction is not None:
        _, pmean, _ = phase_average(d.phase[test], prediction[test] - d.fundamental()[test],
                                    1.0, 38)
        ax_w.plot(centres, pmean, "-", color="C3", label=f"{diagnosis.cause} (fitted before)")
    ax_w.axhline(0.0, color="0.6", lw=0.6)
    ax_w.set_xlabel("phase of the fundamental [rad]")
    ax_w.set_ylabel(f"[{unit}]")
    ax_w.set_xlim(0, 2 * math.pi)
    ax_w.legend(fontsize=7)
    ax_w.set_title("(c) held-out span, one period averaged", fontsize=9)

    names = [f"{c['model']}\n({c['cause']}{', excluded' if c.get('excluded') else ''})"
             for c in diagnosis.candidates]
    gains = [c["gain"] for c in diagnosis.candidates]
    colors = ["C3" if c["cause"] == diagnosis.cause and not c.get("excluded") else "0.6"
              for c in diagnosis.candidates]
    hatch = ["//" if c.get("excluded") else "" for c in diagnosis.candidates]
    bars = ax_g.barh(range(len(gains)), gains, color=colors)
    for bar, h in zip(bars, hatch, strict=True):
        bar.set_hatch(h)
    ax_g.set_yticks(range(len(gains)), names, fontsize=6)
    ax_g.set_xlabel("held-out gain 1 - NRMSE / NRMSE(linear lever)")
    ax_g.set_title("(d) held-out gain (hatched: excluded)", fontsize=9)
    fig.tight_layout()
    return _save(fig, _out_dir(out_dir) / name)
