"""Shared pytest configuration: headless plotting, fixed thread count."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("NUMBA_NUM_THREADS", "2")
