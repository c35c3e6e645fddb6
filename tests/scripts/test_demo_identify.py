"""The demo's identification recording: two set-point series of one tip that read as ONE
experiment and reach different indentations (what bounds the exponent; docs/identify.md)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir

from afmlearn.identify.infer import read_files
from afmlearn.io import read_trace
from afmlearn.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
import demo  # noqa: E402  (scripts/ is not a package)


def test_demo_series_are_one_tip_at_two_free_amplitudes(tmp_path):
    paths = []
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        for name, overrides in demo.IDENTIFY:
            short = [o for o in overrides if not o.startswith("scenario.n_periods")]
            cfg = compose("simulate", overrides=[*short, "scenario.n_periods=10",
                                                 f"output={tmp_path / name}.h5",
                                                 "progress=false"])
            paths.append(simulate(cfg)[0]["output"])
    exp, origin = read_files(paths)                 # one cantilever: no error
    assert len(exp) == 8 and [k for k, _ in origin] == [0] * 4 + [1] * 4
    low, high = (read_trace(p, labels=True) for p in paths)
    np.testing.assert_allclose(high.free_amplitude_m / low.free_amplitude_m, 3.0, rtol=0.02)
    # set-points (rest gap / free amplitude) span the tapping range at both amplitudes
    for tr in (low, high):
        sp = np.asarray(tr.gap_m) / tr.free_amplitude_m
        assert 0.45 < sp.min() and sp.max() < 0.95
    # the deeper indentation of the larger amplitude (truth: smallest tip-sample gap)
    depth = [-np.min(t.labels.extra["tip_sample_gap_m"]) for t in (low, high)]
    assert depth[1] > 1.5 * depth[0] > 0, depth
