"""Figures: one module per subject (traces and sweeps, identification, QRNN)."""

from afmlearn.plots.trace import harmonic_amplitude, plot_sweep, plot_trace

__all__ = ["harmonic_amplitude", "plot_sweep", "plot_trace"]
