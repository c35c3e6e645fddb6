"""``higher_mode`` with the QRNN prior on approach ramps: the network reads steady records
only, so a ramp gets no QRNN evidence (prior 0, said in the evidence text) instead of an
error, and the default hypotheses diagnose a ramp end to end."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from afmlearn.diagnose.hypotheses import HigherMode
from afmlearn.io import Trace, read_trace
from afmlearn.qrnn.evidence import CouplingEvidence

CONF = Path(__file__).resolve().parents[3] / "conf"


def _ramp_and_rows(path):
    tr = read_trace(path)
    rows = [tr.row(i) for i in range(tr.n_points)]
    y = np.concatenate([r.deflection_m for r in rows])
    gap = np.concatenate([np.full(r.deflection_m.size, float(r.gap_m)) for r in rows])
    ramp = Trace(y, **{**rows[0].metadata(), "gap_m": gap, "drive_phase_rad": None})
    return ramp, rows


def _ev(p: float) -> CouplingEvidence:
    one = np.ones(1)
    return CouplingEvidence(probability=p * one, flag=one > 0, raw_score=p * one,
                            forecast_nrmse=0.01 * one, gap_m=1e-8 * one,
                            drive_frequency_hz=1e5 * one, threshold=0.3, false_flag_rate=0.05,
                            calibrated=True, checkpoint="x.ckpt", base_rate=0.2 * one)


def test_ramp_records_get_no_qrnn_evidence_and_say_so(make_series, monkeypatch, caplog):
    ramp, rows = _ramp_and_rows(make_series("none", 3)[0])
    assert ramp.is_ramp and not rows[0].is_ramp
    seen = []

    def fake(trace, **kw):          # the real one raises on a ramp
        if trace.is_ramp:
            raise ValueError("not approach ramps")
        seen.append(trace)
        return _ev(0.9)

    import afmlearn.qrnn.evidence as evidence
    monkeypatch.setattr(evidence, "coupling_probability", fake)
    h = HigherMode(qrnn=True)
    with caplog.at_level("INFO", logger="afmlearn.diagnose.hypotheses.higher_mode"):
        assert h.prior_log_odds(SimpleNamespace(traces=[ramp])) == 0.0
        d = h.details(None, SimpleNamespace(traces=[ramp]))
    assert not seen and d["qrnn_coupling"]["log_odds"] == 0.0
    assert "not consulted" in d["text"] and "ramp" in d["text"]
    assert sum("approach ramps" in r.getMessage() for r in caplog.records) == 1   # once
    # a steady record next to the ramp still counts, the ramp is left out
    both = SimpleNamespace(traces=[ramp, rows[0]])
    assert h.prior_log_odds(both) > 0.0 and seen == [rows[0]]
    assert h.details(None, both)["qrnn_coupling"]["probabilities"] == [0.9]


@pytest.mark.slow
def test_default_hypotheses_diagnose_a_ramp(make_series):
    """The default diagnoser config (HigherMode(qrnn=True) first) on a short ramp: runs, and
    higher_mode's evidence says the QRNN was not consulted (before: ValueError from the
    QRNN after minutes of fitting)."""
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    _, rows = _ramp_and_rows(make_series("none", 3)[0])
    # a slow ramp (1 % of L_ref per settling time, below MAX_RAMP_LAG: causes are tested)
    y = np.concatenate([r.deflection_m for r in rows])
    meta = rows[0].metadata()
    g = float(np.mean([r.gap_m for r in rows]))
    step = 0.01 * g / (meta["quality_factor"] / np.pi) * meta["drive_frequency_hz"] \
        / meta["sample_rate_hz"]
    ramp = Trace(y, **{**meta, "gap_m": g + step * (np.arange(y.size) - y.size / 2),
                       "drive_phase_rad": None})
    cfg = OmegaConf.load(CONF / "diagnoser" / "default.yaml")
    cfg.max_ramp_windows = 3
    dg = instantiate(cfg)
    assert any(getattr(h, "qrnn", False) for h in dg.hypotheses)
    dg.fit(ramp)
    assert {o.kind for o in dg.observations_} == {"ramp_window"}
    hm = next(c for c in dg.candidates_ if c.cause == "higher_mode")
    assert "QRNN not consulted" in hm.evidence
