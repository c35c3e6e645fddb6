"""Sparse-regression optimizers (pysindy-compatible, fitted from Gram matrices)."""

from afmlearn.identify.optimizers.base import (
    GramOptimizer,
    InfeasibleError,
    constrained_lstsq,
    gram_statistics,
)
from afmlearn.identify.optimizers.sr3 import BoxSR3

__all__ = ["BoxSR3", "GramOptimizer", "InfeasibleError", "constrained_lstsq", "gram_statistics"]
