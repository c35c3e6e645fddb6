"""Figures of traces and sweeps in SI units (matplotlib, Agg canvas, PNGs written atomically).

`plot_trace` draws one recording: deflection vs time, the phase portrait, the spectrum with
the drive harmonics and the higher eigenmodes marked, and (for simulated traces) the true
tip--sample force vs time and vs gap. `plot_sweep` draws a frequency sweep: the deflection
envelope (max / min) forward and reverse, the amplitude of one higher harmonic and the modal
coupling strength vs drive frequency.

Both accept a trace file path, a :class:`afmlearn.io.Trace` or a
:class:`simulator.SimulationResult` (then ``scales=`` is required to convert to SI). Figures
are drawn on an explicit Agg canvas, so importing this module never changes the pyplot
backend of the caller.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, final

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray
from scipy.signal import savgol_filter

from afmlearn.io import Trace, TraceReader, read_trace
from afmlearn.io._atomic import atomic_path

__all__ = ["plot_trace", "plot_sweep", "harmonic_amplitude"]

_FORWARD, _REVERSE = "#1f77b4", "#d62728"


# ---------------------------------------------------------------------------- data views
@final
@dataclass(frozen=True)
class _Row:
    """One recording in SI units (what the figures need)."""

    deflection_m: NDArray[np.float64]          # measured, shape (n,)
    sample_rate_hz: float
    drive_frequency_hz: float
    true_deflection_m: NDArray[np.float64] | None = None
    force_n: NDArray[np.float64] | None = None
    tip_gap_m: NDArray[np.float64] | None = None   # instantaneous gap z
    rest_gap_m: float | NDArray[np.float64] | None = None
    free_deflection_m: NDArray[np.float64] | None = None
    higher_mode_frequencies_hz: NDArray[np.float64] | None = None
    a0_m: float | None = None
    title: str = ""

    @property
    def time_s(self) -> NDArray[np.float64]:
        return np.arange(self.deflection_m.shape[-1]) / self.sample_rate_hz

    @property
    def samples_per_period(self) -> float:
        return self.sample_rate_hz / self.drive_frequency_hz


def _a0_from_model(model: dict[str, Any], length_m: float | None) -> float | None:
    """Contact onset [m] from a labels model record (None if it has none)."""
    if not length_m:
        return None
    force = model.get("force", {})
    stack = [force]
    while stack:
        item = stack.pop()
        if not isinstance(item, dict):
            continue
        params = item.get("parameters", {})
        if isinstance(params, dict):
            if "a0" in params:
                return float(params["a0"]) * length_m
            stack.extend(params.get("terms", []))
    return None


def _row_from_trace(trace: Trace, row: int | None) -> _Row:
    i = None
    z_rows = None
    if trace.has_rows:               # a frequency sweep or a set-point series: one row
        i = trace.n_points // 2 if row is None else int(row)
        if not 0 <= i < trace.n_points:
            raise ValueError(f"row must be in [0, {trace.n_points}), got {row}")
        if trace.labels is not None:
            z_rows = trace.labels.extra.get("tip_sample_gap_m")
        trace = trace.row(i)
    if trace.deflection_m is None:
        raise ValueError("trace: no deflection_m to plot (a lock-in amplitude/phase curve)")
    x = trace.deflection_m
    drive = float(trace.drive_frequency_hz)
    lab = trace.labels
    true = force = tip_gap = a0 = None
    if lab is not None:
        force = lab.force_n
        if lab.modal_m is not None:
            true = lab.modal_m.sum(axis=0)
        z = lab.extra.get("tip_sample_gap_m") if z_rows is None else z_rows[i]
        if z is not None and z.shape == x.shape:
            tip_gap = z
        elif true is not None and trace.excitation != "base":
            tip_gap = trace.gap_m - true
        a0 = _a0_from_model(lab.model, lab.model.get("calibration", {}).get("length_m"))
    title = f"drive {drive / 1e3:.3f} kHz" + ("" if i is None else f" (row {i})")
    if i is not None and np.ndim(trace.gap_m) == 0:
        title += f", rest gap {float(trace.gap_m) * 1e9:.2f} nm"
    return _Row(deflection_m=x, sample_rate_hz=trace.sample_rate_hz, drive_frequency_hz=drive,
                true_deflection_m=true, force_n=force, tip_gap_m=tip_gap,
                rest_gap_m=trace.gap_m, free_deflection_m=trace.free_deflection_m,
                higher_mode_frequencies_hz=trace.higher_mode_frequencies_hz, a0_m=a0,
                title=title)


def _row_from_result(result: Any, scales: Any, row: int | None) -> _Row:
    if scales is None:
        raise ValueError("scales is required to plot a SimulationResult in SI units")
    si = result.to_si(scales)
    ell = scales.length
    rows = result.has_rows           # a frequency sweep or a set-point series
    i = (result.q.shape[0] // 2 if row is None else int(row)) if rows else None
    pick = (lambda a: a) if i is None else (lambda a: a[i])
    x = pick(si["deflection_m"])
    drives = np.atleast_1d(si["drive_frequency_hz"])
    drive = float(drives[i] if i is not None and drives.size > 1 else drives[0])
    rest_gap = si["gap_m"]
    if i is not None and np.shape(rest_gap) == (result.q.shape[0],):   # series: gap per row
        rest_gap = float(rest_gap[i])
    cl = result.system.cantilever
    higher = (scales.resonance_frequency * np.asarray(cl.frequency_ratios[1:])
              if cl.n_modes > 1 else None)
    a0 = result.system.force.a0 * ell or None
    return _Row(deflection_m=x, sample_rate_hz=float(si["sample_rate_hz"]),
                drive_frequency_hz=drive, true_deflection_m=x, force_n=pick(si["force_n"]),
                tip_gap_m=pick(result.gap) * ell, rest_gap_m=rest_gap,
                higher_mode_frequencies_hz=higher, a0_m=a0,
                title=f"{result.scenario}: drive {drive / 1e3:.3f} kHz")


def _as_row(source: Any, scales: Any, row: int | None) -> _Row:
    if isinstance(source, str | os.PathLike):
        return _row_from_trace(read_trace(source, labels=True), row)
    if isinstance(source, Trace):
        return _row_from_trace(source, row)
    if hasattr(source, "to_si") and hasattr(source, "system"):
        return _row_from_result(source, scales, row)
    raise ValueError("trace_or_result must be a trace file path, a Trace or a "
                     f"SimulationResult, got {type(source).__name__}")


# ---------------------------------------------------------------------------- helpers
def harmonic_amplitude(x: NDArray[np.float64], sample_rate_hz: float, drive_frequency_hz: float,
                       harmonic: int) -> float:
    """Amplitude of ``x`` at ``harmonic`` times the drive frequency (lock-in).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Signal [any unit]; only whole drive periods (from the start) are used.
    sample_rate_hz, drive_frequency_hz : float
        Sampling rate and drive frequency [Hz].
    harmonic : int
        Harmonic number h >= 1.

    Returns
    -------
    float
        ``|2 mean(x exp(-i 2 pi h f t))|`` in the unit of ``x``.
    """
    n = x.shape[-1]
    spp = sample_rate_hz / drive_frequency_hz
    whole = math.floor(n / spp)
    m = int(round(whole * spp)) if whole >= 1 else n
    t = np.arange(m) / sample_rate_hz
    return float(2.0 * abs(np.mean(x[:m] * np.exp(-2j * np.pi * harmonic * drive_frequency_hz
                                                  * t))))


def _last_periods(r: _Row, periods: float) -> slice:
    n = r.deflection_m.shape[-1]
    m = min(n, max(2, int(round(periods * r.samples_per_period))))
    return slice(n - m, n)


def _lock_in(x: NDArray[np.float64], sample_rate_hz: float, f_hz: float) -> complex:
    """Complex first-harmonic amplitude ``A`` of ``x ~ Re(A exp(i 2 pi f t))``, t from 0."""
    t = np.arange(x.size) / sample_rate_hz
    return complex(2.0 * np.mean(x * np.exp(-2j * np.pi * f_hz * t)))


def _aligned_free(r: _Row, sl: slice) -> NDArray[np.float64]:
    """The free trace shifted so its first harmonic is in phase with ``deflection[sl]``.

    The files do not store the drive phase, so the two records are aligned on their first
    harmonics (this compares amplitude and waveform, not the phase shift of the contact).
    """
    assert r.free_deflection_m is not None
    free = r.free_deflection_m
    m = sl.stop - sl.start
    spp = r.samples_per_period
    whole = max(1, int(math.floor(min(m, free.size) / spp)))
    k = int(round(whole * spp))
    a_main = _lock_in(r.deflection_m[sl][:k], r.sample_rate_hz, r.drive_frequency_hz)
    a_free = _lock_in(free[:k], r.sample_rate_hz, r.drive_frequency_hz)
    lag = (np.angle(a_main) - np.angle(a_free)) % (2.0 * np.pi)
    shift = int(round(lag / (2.0 * np.pi) * spp))
    return free[shift: shift + m]


def _velocity(x: NDArray[np.float64], r: _Row, *, smooth: bool) -> NDArray[np.float64]:
    """dx/dt [m/s]: Savitzky--Golay for measured (noisy) data, central differences otherwise."""
    dt = 1.0 / r.sample_rate_hz
    if not smooth:
        return np.gradient(x, dt)
    win = max(5, int(r.samples_per_period / 12) | 1)
    if win >= x.size:
        return np.gradient(x, dt)
    return savgol_filter(x, win, 3, deriv=1, delta=dt)


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | os.PathLike[str]) -> Path:
    """Write ``fig`` to ``path`` as PNG (folder created), atomically
    (:func:`afmlearn.io._atomic.atomic_path`); the one figure writer of the plots layer."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path


def _out_dir(out_dir: str | os.PathLike[str]) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return out


# ---------------------------------------------------------------------------- plot_trace
def plot_trace(
    trace_or_result: Any,
    out_dir: str | os.PathLike[str],
    *,
    scales: Any = None,
    row: int | None = None,
    prefix: str = "trace",
    periods: float = 5.0,
) -> list[Path]:
    """Draw one recording and save the figures as PNG files.

    Parameters
    ----------
    trace_or_result : str, os.PathLike, Trace or SimulationResult
        A trace file (labels are used when present), a `Trace`, or a simulator result.
    out_dir : str or os.PathLike
        Folder for the figures (created if needed).
    scales : simulator.Scales, optional
        Required for a ``SimulationResult`` (dimensionless) input.
    row : int, optional
        Row of a sweep to draw (default: the middle row).
    prefix : str, default "trace"
        File name prefix: ``{prefix}_deflection.png``, ``_phase_portrait``, ``_spectrum``
        and, with labels, ``_force``.
    periods : float, default 5
        Drive periods shown in the zoomed panels (the phase portrait uses 4x as many).

    Returns
    -------
    list of pathlib.Path
        The PNG files written.
    """
    if not periods > 0:
        raise ValueError(f"periods must be > 0, got {periods!r}")
    r = _as_row(trace_or_result, scales, row)
    out = _out_dir(out_dir)
    paths = [
        _save(_fig_deflection(r, periods), out / f"{prefix}_deflection.png"),
        _save(_fig_phase_portrait(r, 4 * periods), out / f"{prefix}_phase_portrait.png"),
        _save(_fig_spectrum(r), out / f"{prefix}_spectrum.png"),
    ]
    if r.force_n is not None:
        paths.append(_save(_fig_force(r, periods), out / f"{prefix}_force.png"))
    return paths


def _fig_deflection(r: _Row, periods: float) -> Figure:
    fig = _new_figure(9.0, 6.0)
    ax1, ax2 = fig.subplots(2, 1)
    t_us = r.time_s * 1e6
    ax1.plot(t_us, r.deflection_m * 1e9, lw=0.4, color="k", label="measured deflection")
    if r.rest_gap_m is not None and np.ndim(r.rest_gap_m) == 1:
        ax1.plot(t_us, np.asarray(r.rest_gap_m) * 1e9, color="tab:green", lw=1.2,
                 label="rest gap")
    ax1.set_xlabel("time [µs]")
    ax1.set_ylabel("deflection [nm]")
    ax1.set_title(f"Deflection (towards the sample positive) — {r.title}")
    ax1.legend(loc="upper right", fontsize="small")
    sl = _last_periods(r, periods)
    ax2.plot(t_us[sl], r.deflection_m[sl] * 1e9, ".", ms=2, color="0.4", label="measured")
    if r.true_deflection_m is not None:
        ax2.plot(t_us[sl], r.true_deflection_m[sl] * 1e9, lw=1.2, color="tab:blue",
                 label="true (noise-free)")
    if r.free_deflection_m is not None:
        free = _aligned_free(r, sl)
        ax2.plot(t_us[sl][: free.size], free * 1e9, lw=0.8, color="tab:orange", alpha=0.7,
                 label="free (no sample), aligned on the 1st harmonic")
    if r.rest_gap_m is not None and np.ndim(r.rest_gap_m) == 0:
        ax2.axhline(float(r.rest_gap_m) * 1e9, color="tab:green", ls="--", lw=1,
                    label="rest gap (surface)")
    ax2.set_xlabel("time [µs]")
    ax2.set_ylabel("deflection [nm]")
    ax2.set_title(f"Last {periods:g} drive periods")
    ax2.legend(loc="best", fontsize="small")
    return fig


def _fig_phase_portrait(r: _Row, periods: float) -> Figure:
    fig = _new_figure(6.5, 6.0)
    ax = fig.subplots()
    sl = _last_periods(r, periods)
    x = r.deflection_m
    ax.plot(x[sl] * 1e9, _velocity(x, r, smooth=True)[sl] * 1e3, lw=0.5, color="0.5",
            label="measured (Savitzky–Golay)")
    if r.true_deflection_m is not None:
        xt = r.true_deflection_m
        ax.plot(xt[sl] * 1e9, _velocity(xt, r, smooth=False)[sl] * 1e3, lw=1.0,
                color="tab:blue", label="true")
    if r.rest_gap_m is not None and np.ndim(r.rest_gap_m) == 0:
        ax.axvline(float(r.rest_gap_m) * 1e9, color="tab:green", ls="--", lw=1,
                   label="rest gap (surface)")
    ax.set_xlabel("deflection x [nm]")
    ax.set_ylabel("velocity dx/dt [mm/s]")
    ax.set_title(f"Phase portrait, last {periods:g} periods — {r.title}")
    ax.legend(loc="upper right", fontsize="small")
    return fig


def _fig_spectrum(r: _Row) -> Figure:
    fig = _new_figure(9.0, 4.8)
    ax = fig.subplots()
    n = r.deflection_m.size
    win = np.hanning(n)

    def spectrum(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return 2.0 * np.abs(np.fft.rfft((x - np.mean(x)) * win)) / win.sum()

    amp = spectrum(r.deflection_m)
    f = np.fft.rfftfreq(n, 1.0 / r.sample_rate_hz) / r.drive_frequency_hz
    top = 25.0
    if r.higher_mode_frequencies_hz is not None:
        top = max(top, 1.2 * float(np.max(r.higher_mode_frequencies_hz)) / r.drive_frequency_hz)
    top = min(top, f[-1])
    keep = (f > 0) & (f <= top)
    ax.semilogy(f[keep], np.maximum(amp[keep], 1e-30) * 1e9, lw=0.7, color="k",
                label="measured (Hann window)")
    if r.true_deflection_m is not None and r.true_deflection_m is not r.deflection_m:
        ax.semilogy(f[keep], np.maximum(spectrum(r.true_deflection_m)[keep], 1e-30) * 1e9,
                    lw=0.8, color="tab:blue", alpha=0.8, label="true (noise-free)")
    for h in range(1, int(top) + 1):
        ax.axvline(h, color="0.75", lw=0.6, ls=":", zorder=0)
    ax.plot([], [], color="0.6", ls=":", label="n · f_drive")
    if r.higher_mode_frequencies_hz is not None:
        for k, fk in enumerate(np.atleast_1d(r.higher_mode_frequencies_hz), start=2):
            ax.axvline(fk / r.drive_frequency_hz, color="tab:red", ls="--", lw=1.0,
                       label=f"f{k} = {fk / 1e3:.1f} kHz")
    ax.set_xlim(0, top)
    ax.set_xlabel("frequency / drive frequency")
    ax.set_ylabel("amplitude [nm]")
    ax.set_title(f"Amplitude spectrum of the deflection — {r.title}")
    ax.legend(loc="upper right", fontsize="small")
    return fig


def _fig_force(r: _Row, periods: float) -> Figure:
    assert r.force_n is not None
    fig = _new_figure(11.0, 4.8)
    ax1, ax2 = fig.subplots(1, 2)
    sl = _last_periods(r, periods)
    t_us = r.time_s * 1e6
    ax1.plot(t_us[sl], r.force_n[sl] * 1e9, lw=1.0, color="k")
    ax1.axhline(0.0, color="0.7", lw=0.6)
    ax1.set_xlabel("time [µs]")
    ax1.set_ylabel("tip–sample force [nN] (> 0 repulsive)")
    ax1.set_title(f"True force, last {periods:g} periods")
    if r.tip_gap_m is not None:
        long = _last_periods(r, 4 * periods)
        z = r.tip_gap_m[long]
        f = r.force_n[long]
        dz = np.gradient(z)
        ax2.plot(z[dz < 0] * 1e9, f[dz < 0] * 1e9, ".", ms=2.5, color=_FORWARD,
                 label="approach (gap closing)")
        ax2.plot(z[dz >= 0] * 1e9, f[dz >= 0] * 1e9, ".", ms=2.5, color=_REVERSE,
                 label="retraction (gap opening)")
        if r.a0_m is not None:
            ax2.axvline(r.a0_m * 1e9, color="0.4", ls="--", lw=1, label="a0 (contact onset)")
        ax2.axhline(0.0, color="0.7", lw=0.6)
        lo = float(np.min(z))
        span = max(4.0 * (r.a0_m or 0.0) - lo, 0.25 * (float(np.max(z)) - lo))
        ax2.set_xlim(lo * 1e9 - 0.05 * span * 1e9, (lo + span) * 1e9)
        ax2.set_xlabel("tip–sample gap z [nm]")
        ax2.set_ylabel("tip–sample force [nN]")
        ax2.set_title("Force vs gap (near the surface)")
        ax2.legend(loc="upper right", fontsize="small")
    else:
        ax2.set_axis_off()
    return fig


# ---------------------------------------------------------------------------- plot_sweep
@final
@dataclass(frozen=True)
class _SweepRows:
    drive_hz: NDArray[np.float64]
    x_max_m: NDArray[np.float64]
    x_min_m: NDArray[np.float64]
    harmonic_m: NDArray[np.float64]
    true_harmonic_m: NDArray[np.float64] | None
    coupling: NDArray[np.float64] | None
    higher_mode_frequencies_hz: NDArray[np.float64] | None


#: one sweep row: measured deflection [m], true deflection [m] or None, coupling or None
_RowData = tuple[NDArray[np.float64], NDArray[np.float64] | None, float | None]


def _file_rows(reader: TraceReader) -> Iterator[_RowData]:
    for tr in reader:  # one row in memory at a time
        lab = tr.labels
        if lab is None:
            yield tr.deflection_m, None, None
            continue
        true = lab.modal_m.sum(axis=0) if lab.modal_m is not None else None
        c = lab.scalars.get("coupling_strength")
        yield tr.deflection_m, true, None if c is None else float(c)


def _array_rows(x: NDArray[np.float64], true: NDArray[np.float64] | None,
                coupling: Any) -> Iterator[_RowData]:
    cp = None if coupling is None else np.asarray(coupling, dtype=float)
    for i in range(x.shape[0]):
        yield (x[i], None if true is None else true[i],
               None if cp is None or cp.ndim != 1 else float(cp[i]))


def _sweep_rows(source: Any, scales: Any, harmonic: int) -> _SweepRows:
    if isinstance(source, str | os.PathLike):
        with TraceReader(source, labels=True) as reader:
            if not reader.is_sweep:
                raise ValueError(f"sweep: {source} holds a single trace, not a sweep")
            meta = reader.metadata
            return _collect(_file_rows(reader), meta["sample_rate_hz"],
                            meta["drive_frequency_hz"], meta["higher_mode_frequencies_hz"],
                            harmonic)
    if isinstance(source, Trace):
        if not source.is_sweep:
            raise ValueError("sweep: the Trace is a single trace, not a sweep")
        lab = source.labels
        true = lab.modal_m.sum(axis=0) if lab is not None and lab.modal_m is not None else None
        coupling = lab.scalars.get("coupling_strength") if lab is not None else None
        return _collect(_array_rows(source.deflection_m, true, coupling),
                        source.sample_rate_hz, source.drive_frequency_hz,
                        source.higher_mode_frequencies_hz, harmonic)
    if hasattr(source, "to_si") and hasattr(source, "system"):
        if not source.is_sweep:
            raise ValueError("sweep: the SimulationResult is not a sweep")
        if scales is None:
            raise ValueError("scales is required to plot a SimulationResult in SI units")
        si = source.to_si(scales)
        cl = source.system.cantilever
        higher = (scales.resonance_frequency * np.asarray(cl.frequency_ratios[1:])
                  if cl.n_modes > 1 else None)
        return _collect(_array_rows(si["deflection_m"], None,
                                    si["labels"]["coupling_strength"]),
                        float(si["sample_rate_hz"]), si["drive_frequency_hz"], higher, harmonic)
    raise ValueError("sweep must be a trace file path, a Trace or a SimulationResult, got "
                     f"{type(source).__name__}")


def _collect(rows: Iterator[_RowData], sample_rate_hz: float, drive_hz: Any, higher: Any,
             harmonic: int) -> _SweepRows:
    """Per-row envelope, harmonic amplitude and coupling (rows consumed one by one)."""
    drive = np.asarray(drive_hz, dtype=float)
    xmax, xmin, harm, true_harm, coup = (np.full(drive.size, np.nan) for _ in range(5))
    for i, (x, true, c) in enumerate(rows):
        xmax[i], xmin[i] = np.max(x), np.min(x)
        harm[i] = harmonic_amplitude(x, sample_rate_hz, float(drive[i]), harmonic)
        if true is not None:
            true_harm[i] = harmonic_amplitude(true, sample_rate_hz, float(drive[i]), harmonic)
        if c is not None:
            coup[i] = c
    return _SweepRows(
        drive, xmax, xmin, harm,
        None if np.all(np.isnan(true_harm)) else true_harm,
        None if np.all(np.isnan(coup)) else coup,
        None if higher is None else np.atleast_1d(np.asarray(higher, dtype=float)))


def _directions(drive: NDArray[np.float64]) -> list[tuple[str, slice]]:
    """Split rows into monotonic runs: ``("forward" | "reverse", rows)``."""
    runs: list[tuple[str, slice]] = []
    start = 0
    n = drive.size
    while start < n:
        stop = start + 1
        up = True
        if stop < n and drive[stop] != drive[start]:
            up = bool(drive[stop] > drive[start])
            while stop < n and (drive[stop] > drive[stop - 1] if up
                                else drive[stop] < drive[stop - 1]):
                stop += 1
        runs.append(("forward" if up else "reverse", slice(start, stop)))
        start = stop
    return runs


def plot_sweep(
    sweep: Any,
    out_dir: str | os.PathLike[str],
    *,
    scales: Any = None,
    harmonic: int = 6,
    prefix: str = "sweep",
) -> list[Path]:
    """Draw a frequency sweep and save it as a PNG file.

    Panels vs drive frequency [kHz]: the deflection envelope (max and min deflection [nm])
    for the forward and reverse sweep; the amplitude of harmonic ``harmonic`` [nm] (6: the
    6:1 internal resonance with the 2nd eigenmode, marked at ``f2 / harmonic`` when ``f2``
    is known); the coupling strength (share of the motion in modes >= 2, from the labels).

    Parameters
    ----------
    sweep : str, os.PathLike, Trace or SimulationResult
        A sweep file (streamed row by row), a sweep `Trace`, or a simulator sweep result.
    out_dir : str or os.PathLike
        Folder for the figure (created if needed).
    scales : simulator.Scales, optional
        Required for a ``SimulationResult``.
    harmonic : int, default 6
        Harmonic whose amplitude is drawn (>= 2).
    prefix : str, default "sweep"
        The file is ``{prefix}.png``.

    Returns
    -------
    list of pathlib.Path
        The PNG file written.
    """
    if isinstance(harmonic, bool) or not isinstance(harmonic, int) or harmonic < 2:
        raise ValueError(f"harmonic must be an integer >= 2, got {harmonic!r}")
    rows = _sweep_rows(sweep, scales, harmonic)
    out = _out_dir(out_dir)
    fig = _new_figure(9.0, 9.0)
    axes = fig.subplots(3, 1, sharex=True)
    f_khz = rows.drive_hz / 1e3
    for direction, sl in _directions(rows.drive_hz):
        color = _FORWARD if direction == "forward" else _REVERSE
        style = "-" if direction == "forward" else "--"
        axes[0].plot(f_khz[sl], rows.x_max_m[sl] * 1e9, style, color=color, lw=1.2,
                     label=f"{direction}: max")
        axes[0].plot(f_khz[sl], rows.x_min_m[sl] * 1e9, style, color=color, lw=0.8,
                     alpha=0.6, label=f"{direction}: min")
        axes[1].semilogy(f_khz[sl], np.maximum(rows.harmonic_m[sl], 1e-30) * 1e9, style,
                         color=color, lw=1.2, label=f"{direction}: measured")
        if rows.true_harmonic_m is not None:
            axes[1].semilogy(f_khz[sl], np.maximum(rows.true_harmonic_m[sl], 1e-30) * 1e9,
                             style, color=color, lw=0.8, alpha=0.5,
                             label=f"{direction}: true (labels)")
        if rows.coupling is not None:
            axes[2].plot(f_khz[sl], rows.coupling[sl], style, color=color, lw=1.2,
                         label=direction)
    axes[0].set_ylabel("deflection [nm]")
    axes[0].set_title("Deflection envelope (max / min) vs drive frequency")
    axes[0].legend(loc="best", fontsize="small", ncols=2)
    axes[1].set_ylabel(f"harmonic {harmonic} amplitude [nm]")
    axes[1].set_title(f"Amplitude of harmonic {harmonic} of the deflection")
    if rows.higher_mode_frequencies_hz is not None:
        f_res = float(np.atleast_1d(rows.higher_mode_frequencies_hz)[0]) / harmonic
        if f_khz.min() <= f_res / 1e3 <= f_khz.max():
            for ax in axes:
                ax.axvline(f_res / 1e3, color="0.4", ls=":", lw=1)
            axes[1].plot([], [], color="0.4", ls=":", label=f"f2 / {harmonic}")
    axes[1].legend(loc="best", fontsize="small")
    axes[2].set_ylabel("coupling strength [-]")
    axes[2].set_xlabel("drive frequency [kHz]")
    if rows.coupling is not None:
        axes[2].set_title("Share of the tip motion in modes >= 2 (labels)")
        axes[2].legend(loc="best", fontsize="small")
    else:
        axes[2].set_title("Coupling strength: not available (no labels)")
    return [_save(fig, out / f"{prefix}.png")]
