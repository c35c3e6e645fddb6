"""Backward check of named causes: each one taken out of the final model, dropped if it is
not needed there (the step-wise selection's second direction; docs/diagnose.md, "Backward
check of named causes"). The refits are the :class:`~afmlearn.diagnose.Diagnoser`'s; this
module holds the decision and its bookkeeping, pure functions of the chi2 rises and gains."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import final

__all__ = ["Removal", "backward_eliminate", "backward_keep"]


@final
@dataclass(frozen=True)
class Removal:
    """The backward check of one named cause: the final model refitted without it.

    ``chi2_rise``: output-error chi2 of that refit minus the final model's; ``threshold``:
    the one the cause was named with (null threshold minus twice its prior log-odds);
    ``gain``: its held-out gain in the final model, ``1 - NRMSE(final) / NRMSE(without it)``
    (NaN: not computed, the chi2 rise already dropped it); ``reason``: why it was dropped
    (empty: kept).
    """

    cause: str
    chi2_rise: float
    threshold: float
    gain: float
    reason: str

    @property
    def kept(self) -> bool:
        return not self.reason


def backward_keep(chi2_rise: float, threshold: float, gain: float, min_gain: float) -> str:
    """The backward check's decision for one named cause: ``""`` (keep) or why it is dropped.

    Dropped when removing it from the final model (the rest refitted) raises chi2 by no more
    than ``threshold`` (the one it was named with), or when its held-out gain in the final
    model is not above ``min_gain`` (NaN counts as not above). A NaN rise is no evidence.
    """
    if not chi2_rise > threshold:
        return (f"chi2 rises by {chi2_rise:.1f} when it is removed from the final model, not "
                f"above its threshold {threshold:.2f}")
    if not gain > min_gain:
        return (f"held-out gain {gain:+.3f} in the final model, not above {min_gain:g}")
    return ""


def backward_eliminate(causes: Sequence[str], thresholds: Sequence[float], min_gain: float,
                       remove: Callable[[int, tuple[int, ...]], tuple[float,
                                                                      Callable[[], float]]],
                       accept: Callable[[int], None]) -> tuple[list[int], list[Removal],
                                                              dict[int, Removal]]:
    """Backward elimination of named causes (indices into ``causes``, in naming order).

    The kept causes are checked the last named first. ``remove(i, kept)`` refits the current
    final model (the kept causes ``kept``) without cause ``i`` and returns the chi2 rise and
    a callable giving ``i``'s held-out gain in the final model (called only when the rise is
    above the threshold: it costs refits without the held-out set-points). A dropped cause is
    committed by ``accept(i)`` (the refit without it becomes the final model); every cause
    kept so far is then checked again against the new final model, until every kept cause
    has been checked against the current one (a pass that drops nothing).

    Returns the kept indices (naming order), the dropped causes' records (in the order
    dropped) and the last record of each kept one.
    """
    if len(causes) != len(thresholds):
        raise ValueError(f"thresholds must have one value per cause ({len(causes)}), got "
                         f"{len(thresholds)}")
    kept = list(range(len(causes)))
    version = 0
    checked: dict[int, int] = {}
    last: dict[int, Removal] = {}
    dropped: list[Removal] = []
    while True:
        todo = [i for i in reversed(kept) if checked.get(i) != version]
        if not todo:
            break
        i = todo[0]
        rise, gain_of = remove(i, tuple(kept))
        gain = gain_of() if rise > thresholds[i] else math.nan
        reason = backward_keep(rise, thresholds[i], gain, min_gain)
        rec = Removal(cause=causes[i], chi2_rise=float(rise), threshold=float(thresholds[i]),
                      gain=float(gain), reason=reason)
        if reason:
            accept(i)
            kept.remove(i)
            dropped.append(rec)
            last.pop(i, None)
            version += 1
        else:
            checked[i] = version
            last[i] = rec
    return kept, dropped, last
