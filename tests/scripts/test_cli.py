"""scripts/_cli.py: the one bad-input wrapper of the entry points."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location(
    "_cli", Path(__file__).resolve().parents[2] / "scripts" / "_cli.py")
_cli = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_cli)
bad_input_exits, error_line = _cli.bad_input_exits, _cli.error_line


def test_error_line_is_one_line():
    assert error_line(ValueError("a\n  b\n\nc")) == "error: a   b c"
    assert error_line(ValueError("plain")) == "error: plain"
    assert error_line(OSError()) == "error: OSError"


def test_bad_input_exits_2_with_one_line_and_lets_other_errors_through(capsys):
    with pytest.raises(SystemExit) as exc, bad_input_exits():
        raise ValueError("row must be null\nor an integer")
    assert exc.value.code == 2
    assert capsys.readouterr().err == "error: row must be null or an integer\n"
    with pytest.raises(SystemExit) as exc, bad_input_exits(ValueError, OSError):
        raise FileNotFoundError("no such file")
    assert exc.value.code == 2 and capsys.readouterr().err == "error: no such file\n"
    with pytest.raises(KeyError), bad_input_exits():  # a bug is not bad input
        raise KeyError("x")
    with bad_input_exits():
        pass
    assert capsys.readouterr().err == ""
