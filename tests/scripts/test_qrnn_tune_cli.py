"""scripts/infer_qrnn.py, tune.py and train_qrnn.py: one line ``error: ...`` and exit 2 on
bad input (through the shared ``_cli.bad_input_exits``, so a multi-line message stays one
line)."""

from __future__ import annotations


def test_infer_qrnn_missing_trace_is_one_error_line(tmp_path, run_script):
    line = run_script.error_line("infer_qrnn.py", f"trace={tmp_path / 'none.h5'}",
                                 f"out_dir={tmp_path / 'out'}")
    assert "none.h5" in line
    assert not (tmp_path / "out" / "coupling.json").exists()


def test_tune_missing_recording_is_one_error_line(tmp_path, run_script):
    line = run_script.error_line("tune.py", f"recording={tmp_path / 'none.h5'}",
                                 f"hydra.run.dir={tmp_path / 'run'}")
    assert "none.h5" in line


def test_train_qrnn_bad_data_setting_is_one_error_line(tmp_path, run_script):
    """Hydra wraps the data module's ValueError; train() raises it again naming the key."""
    line = run_script.error_line("train_qrnn.py", "data=qrnn_tiny", "data.spec.modes=[7]",
                                 f"hydra.run.dir={tmp_path / 'run'}",
                                 f"paths.output_dir={tmp_path / 'out'}")
    assert line.startswith("error: data: modes must be")
