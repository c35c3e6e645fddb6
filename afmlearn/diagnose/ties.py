"""Ties between candidate causes: whether the data separate the named cause from another.

Two candidates fitted to the same orbits are compared twice (:func:`~afmlearn.diagnose.
naming.name_cause`): by their output-error chi-square (in-sample) and, when that is a tie,
by their held-out NRMSE on set-points never fitted. Each comparison has its own noise:

* **chi2.** Both fits see the same noise ``e`` (whitened: unit variance per residual row).
  For fits ``m_a``, ``m_b`` of the noise-free data ``mu``, ``chi2_a - chi2_b =
  ||m_a - mu||^2 - ||m_b - mu||^2 - 2 e . (m_a - m_b)``, so a new noise draw moves the
  difference by a standard deviation ``2 ||m_a - m_b|| = 2 ||r_a - r_b||`` (the residual
  vectors' difference; the refits absorb part of it, so this is an upper estimate). Two
  fits that predict nearly the same orbits have a small difference *and* a small spread;
  fits that differ a lot can swap places under a new draw even with a large difference.
* **held-out.** One NRMSE per held-out set-point; the median decides. Its uncertainty is
  read from the set-points themselves: the named candidate predicts better at ``k`` of ``n``
  of them; a two-sided sign test (``p`` < ``HELDOUT_ALPHA``) says whether that is more than
  chance. With 4 held-out set-points it never is (p >= 0.125); with 8 only 8 of 8 is.

A candidate is *not separated* from the named one when the chi2 does not separate them
(within ``max(tie margin, TIE_SD * sd)``, the margin the naming rule uses) and the held-out
set-points do not either: the diagnosis then says so (``report.json`` ``not_separated``,
``report.md``) instead of pretending.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import final

import numpy as np
from numpy.typing import NDArray
from scipy import stats

__all__ = ["HELDOUT_ALPHA", "TIE_SD", "Tie", "chi2_difference_sd", "heldout_sign_test"]

#: standard deviations of the chi2 difference within which two candidates are a tie
TIE_SD = 2.0

#: two-sided sign-test level at which the held-out set-points separate two candidates
HELDOUT_ALPHA = 0.05


@final
@dataclass(frozen=True)
class Tie:
    """A candidate the data do not separate from the named cause (one step).

    ``cause``: the other candidate; ``delta_chi2`` / ``named_delta_chi2``: its and the named
    cause's chi2 drops; ``chi2_sd``: standard deviation of their chi2 difference under a new
    noise draw (:func:`chi2_difference_sd`; NaN: not known); ``heldout_nrmse`` /
    ``named_heldout_nrmse``: median held-out NRMSE (NaN: not computed); ``better_at``, ``n``,
    ``p``: the named cause predicts better at ``better_at`` of ``n`` held-out set-points,
    two-sided sign-test p-value ``p`` (:func:`heldout_sign_test`).
    """

    cause: str
    delta_chi2: float
    named_delta_chi2: float
    chi2_sd: float
    heldout_nrmse: float
    named_heldout_nrmse: float
    better_at: int
    n: int
    p: float

    def text(self, named: str) -> str:
        """One line for people: ``"named; not separated from X on these data (...)"``."""
        held = (f"held-out NRMSE {self.named_heldout_nrmse:.3g} vs {self.heldout_nrmse:.3g}, "
                f"better at {self.better_at} of {self.n} held-out set-points"
                if self.n else "no held-out comparison")
        sd = f", chi2 noise sd {self.chi2_sd:.0f}" if math.isfinite(self.chi2_sd) else ""
        return (f"{named}; not separated from {self.cause} on these data (drops "
                f"{self.named_delta_chi2:.0f} vs {self.delta_chi2:.0f}{sd}; {held})")


def chi2_difference_sd(r_a: NDArray[np.float64], r_b: NDArray[np.float64]) -> float:
    """Standard deviation of ``chi2_a - chi2_b`` under a new noise draw of the same data:
    ``2 ||r_a - r_b||`` for whitened residual vectors of the two fits (NaN when they do not
    have the same rows or are not finite)."""
    a = np.asarray(r_a, float).reshape(-1)
    b = np.asarray(r_b, float).reshape(-1)
    if a.shape != b.shape or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return math.nan
    return float(2.0 * np.linalg.norm(a - b))


def heldout_sign_test(named: Sequence[float], other: Sequence[float]) -> tuple[int, int, float]:
    """Per held-out set-point NRMSE of the named and another candidate: at how many the named
    one predicts better, over how many set-points both were predicted (finite values; equal
    values left out), and the two-sided sign-test p-value (1 when there are none)."""
    a = np.asarray(named, float).reshape(-1)
    b = np.asarray(other, float).reshape(-1)
    if a.shape != b.shape:
        raise ValueError(f"named and other must have one value per observation, got "
                         f"{a.size} and {b.size}")
    ok = np.isfinite(a) & np.isfinite(b) & (a != b)
    n = int(ok.sum())
    k = int(np.sum(a[ok] < b[ok]))
    p = float(stats.binomtest(k, n, 0.5).pvalue) if n else 1.0
    return k, n, p
