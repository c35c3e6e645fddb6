"""Backward check of named causes: each one taken out of the final model, dropped if it is
not needed there (the step-wise selection's second direction; docs/diagnose.md, "Backward
check of named causes"). The refits are the :class:`~afmlearn.diagnose.Diagnoser`'s; this
module holds the decision and its bookkeeping, pure functions of the chi2 rises and gains."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import final

__all__ = ["OVERWHELMING", "Removal", "backward_eliminate", "backward_keep", "overwhelming"]

#: a removal's chi2 rise this many times above its threshold, after scaling by the final
#: model's misfit (:func:`overwhelming`), is in-sample evidence no held-out gain refutes.
#: Measured: the null series' first-step drops that passed their threshold reached 1.15 of it
#: (60 nulls, 11.3 / 9.88, refuted by the gain); the real detector of the damping + detector
#: dev draw [3, 78] rose 35,865 in a final model of chi2 3,952 with the wrong first cause
OVERWHELMING = 10.0


@final
@dataclass(frozen=True)
class Removal:
    """The backward check of one named cause: the final model refitted without it.

    ``chi2_rise``: output-error chi2 of that refit minus the final model's; ``threshold``:
    the one the cause was named with (null threshold minus twice its prior log-odds);
    ``gain``: its held-out gain in the final model, ``1 - NRMSE(final) / NRMSE(without it)``
    (NaN: not computed, the chi2 rise already dropped it); ``decision_gain``: the gain on
    the cause's own signature in the final model when its hypothesis measures one
    (``AbstractHypothesis.heldout_gain``; it then decides, as in the forward step; NaN:
    ``gain`` decided); ``reason``: why it was dropped (empty: kept).
    """

    cause: str
    chi2_rise: float
    threshold: float
    gain: float
    reason: str
    note: str = ""
    decision_gain: float = math.nan

    @property
    def kept(self) -> bool:
        return not self.reason

    @property
    def deciding_gain(self) -> float:
        """The gain the decision read: ``decision_gain`` when measured, else ``gain``."""
        return self.gain if math.isnan(self.decision_gain) else self.decision_gain


def overwhelming(chi2_rise: float, threshold: float, dispersion: float = 1.0) -> bool:
    """Whether a removal's chi2 rise is beyond what a held-out gain can refute.

    ``dispersion`` is the final model's misfit scale ``chi2 / residual rows`` (values below 1
    count as 1): a model that misses the data by more than their noise inflates every chi2
    difference by about that factor (quasi-likelihood), so the rise is read in its units. A
    rise above :data:`OVERWHELMING` times the threshold in those units is not an over-fit of
    noise or of a misfit the final model leaves (the over-fits the held-out gain exists to
    catch reach ~1 threshold, measured on null series).
    """
    scale = max(float(dispersion), 1.0) if math.isfinite(dispersion) else math.inf
    return bool(chi2_rise / scale > OVERWHELMING * threshold)


def backward_keep(chi2_rise: float, threshold: float, gain: float, min_gain: float, *,
                  dispersion: float = 1.0, own: float = math.nan) -> str:
    """The backward check's decision for one named cause: ``""`` (keep) or why it is dropped.

    Dropped when removing it from the final model (the rest refitted) raises chi2 by no more
    than ``threshold`` (the one it was named with), or when its held-out gain in the final
    model is not above ``min_gain`` (NaN counts as not above) while the rise is not
    :func:`overwhelming` (``dispersion``: the final model's misfit scale). A NaN rise is no
    evidence. The gain is the one the cause's forward step decided on: ``own`` (its gain on
    its own signature, :class:`Removal` ``decision_gain``) when measured, else ``gain`` (the
    NRMSE gain).

    Why an overwhelming rise is kept against the gain: the gain compares the final model with
    the final model without the cause, both refitted without the held-out set-points and
    predicting them; it refutes a cause whose in-sample evidence is an over-fit (the rise just
    above the threshold). A cause that the in-sample data need by far (the real detector of
    a dev draw: rise 35,865, threshold 9.88) and that still predicts held-out set-points worse
    says that the *rest* of the final model extrapolates badly (there a wrong first cause,
    visco-elastic for a damping: the final model predicted two of four held-out set-points at
    NRMSE 0.21), not that this cause is absent.
    """
    if not chi2_rise > threshold:
        return (f"chi2 rises by {chi2_rise:.1f} when it is removed from the final model, not "
                f"above its threshold {threshold:.2f}")
    deciding = gain if math.isnan(own) else own
    if not deciding > min_gain and not overwhelming(chi2_rise, threshold, dispersion):
        return f"held-out gain {_gain_text(gain, own)} in the final model, not above {min_gain:g}"
    return ""


def _gain_text(gain: float, own: float) -> str:
    """``+0.123`` (the NRMSE gain decided) or ``+0.800 on its own signature (NRMSE -0.100)``."""
    if math.isnan(own):
        return f"{gain:+.3f}"
    return f"{own:+.3f} on its own signature (NRMSE {gain:+.3f})"


def _conflict(chi2_rise: float, threshold: float, gain: float, min_gain: float,
              dispersion: float, own: float) -> str:
    """The note of a cause kept by its overwhelming rise against its held-out gain."""
    if (gain if math.isnan(own) else own) > min_gain or not chi2_rise > threshold:
        return ""
    return (f"kept although its held-out gain in the final model is {_gain_text(gain, own)}: "
            f"removing it "
            f"raises chi2 by {chi2_rise:.1f}, {chi2_rise / max(dispersion, 1.0) / threshold:.0f} "
            f"times its threshold {threshold:.2f} at the final model's misfit scale "
            f"{max(dispersion, 1.0):.2f}; the final model's held-out predictions are poor, "
            f"which points at another of its causes")


def backward_eliminate(causes: Sequence[str], thresholds: Sequence[float], min_gain: float,
                       remove: Callable[[int, tuple[int, ...]],
                                        tuple[float, Callable[[], tuple[float, float]],
                                              float]],
                       accept: Callable[[int], None]) -> tuple[list[int], list[Removal],
                                                              dict[int, Removal]]:
    """Backward elimination of named causes (indices into ``causes``, in naming order).

    The kept causes are checked the last named first. ``remove(i, kept)`` refits the current
    final model (the kept causes ``kept``) without cause ``i`` and returns the chi2 rise, a
    callable giving ``i``'s held-out gains in the final model, ``(NRMSE gain, own gain or
    NaN)`` (called only when the rise is above the threshold: it costs refits without the
    held-out set-points; the own gain decides when measured, :func:`backward_keep`) and the
    final model's misfit scale (:func:`overwhelming`). A dropped cause is
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
        rise, gain_of, disp = remove(i, tuple(kept))
        gain, own = gain_of() if rise > thresholds[i] else (math.nan, math.nan)
        reason = backward_keep(rise, thresholds[i], gain, min_gain, dispersion=disp, own=own)
        rec = Removal(cause=causes[i], chi2_rise=float(rise), threshold=float(thresholds[i]),
                      gain=float(gain), reason=reason, decision_gain=float(own),
                      note="" if reason else _conflict(rise, thresholds[i], gain, min_gain,
                                                       disp, own))
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
