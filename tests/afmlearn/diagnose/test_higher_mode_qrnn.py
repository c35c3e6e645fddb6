"""QRNN evidence of the ``higher_mode`` hypothesis: the prior log-odds it adds to the decision
(positive evidence only, in range only, weighted and capped) and its plumbing."""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from afmlearn.diagnose.hypotheses import higher_mode as hm
from afmlearn.diagnose.hypotheses.base import AbstractHypothesis
from afmlearn.diagnose.hypotheses.higher_mode import (
    QRNN_MAX_LOG_ODDS,
    HigherMode,
    qrnn_log_odds,
)
from afmlearn.qrnn.evidence import CouplingEvidence


def _ev(p, *, base=0.2, nrmse=0.03) -> CouplingEvidence:
    p = np.atleast_1d(np.asarray(p, float))
    n = p.size
    return CouplingEvidence(probability=p, flag=p >= 0.3, raw_score=p,
                            forecast_nrmse=np.full(n, nrmse), gap_m=np.full(n, 1e-8),
                            drive_frequency_hz=np.full(n, 1e5), threshold=0.3,
                            false_flag_rate=0.05, calibrated=True, checkpoint="x.ckpt",
                            base_rate=np.full(n, base))


def _logit(v: float) -> float:
    return float(np.log(v / (1 - v)))


def test_log_odds_is_the_weighted_positive_likelihood_ratio():
    # Bayes: posterior 0.8 under a base rate of 0.2 -> LLR = logit(0.8) - logit(0.2) = 2 ln 4
    assert qrnn_log_odds(_ev(0.8), weight=1.0) == pytest.approx(2 * np.log(4.0))
    assert qrnn_log_odds(_ev(0.8), weight=0.5) == pytest.approx(np.log(4.0))
    # the strongest observation of a series counts
    assert qrnn_log_odds(_ev([0.1, 0.8, 0.5]), weight=1.0) == pytest.approx(2 * np.log(4.0))
    # below the base rate: no evidence against the cause (a weak mode is invisible to it)
    assert qrnn_log_odds(_ev([0.01, 0.19]), weight=1.0) == 0.0
    # capped; out of range (forecast worse than QRNN_MAX_FORECAST_NRMSE): nothing
    assert qrnn_log_odds(_ev(0.99999), weight=1.0) == QRNN_MAX_LOG_ODDS
    assert qrnn_log_odds(_ev(0.8, nrmse=0.5), weight=1.0) == 0.0
    # uncalibrated (NaN base rate): nothing
    assert qrnn_log_odds(_ev(0.8, base=np.nan), weight=1.0) == 0.0
    with pytest.raises(ValueError, match="weight"):
        qrnn_log_odds(_ev(0.8), weight=-1.0)
    assert _ev(0.8).log_likelihood_ratio()[0] == pytest.approx(_logit(0.8) - _logit(0.2))


@dataclass
class _Trace:
    deflection_m: np.ndarray
    gap_m: float = 1e-8       # one rest gap: a steady record (ramps get no QRNN evidence)


def test_hypothesis_prior_uses_each_record_once_and_only_when_asked(monkeypatch):
    calls = []

    def fake(trace, **kw):
        calls.append(trace)
        return _ev(0.9 if trace.deflection_m[0] > 0 else 0.05)

    import afmlearn.qrnn.evidence as evidence
    monkeypatch.setattr(evidence, "coupling_probability", fake)
    probe = SimpleNamespace(traces=[_Trace(np.ones(8)), _Trace(-np.ones(8))])
    assert AbstractHypothesis.prior_log_odds(HigherMode(), probe) == 0.0
    assert HigherMode().prior_log_odds(probe) == 0.0 and not calls     # qrnn off: not run
    assert HigherMode(qrnn=True, qrnn_weight=0.0).prior_log_odds(probe) == 0.0
    h = HigherMode(qrnn=True)
    want = hm.QRNN_WEIGHT * (_logit(0.9) - _logit(0.2))
    assert h.prior_log_odds(probe) == pytest.approx(want)
    d = h.details(None, probe)
    assert len(calls) == 2                    # evidence computed once for both calls
    assert d["qrnn_coupling"]["log_odds"] == pytest.approx(want)
    assert d["qrnn_coupling"]["probabilities"] == [0.9, 0.05] and "log-odds" in d["text"]
    # other records (same object ids possible after garbage collection): recomputed
    probe2 = SimpleNamespace(traces=[_Trace(-2 * np.ones(8))])
    assert h.prior_log_odds(probe2) == 0.0 and len(calls) == 3
    with pytest.raises(ValueError, match="qrnn_weight"):
        HigherMode(qrnn=True, qrnn_weight=-0.1)
