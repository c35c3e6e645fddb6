"""Running an entry point of scripts/ in this process, and its bad-input contract.

Every entry point exits with status 2 and prints exactly one line ``error: ...`` (no
traceback) on bad input; :meth:`ScriptRunner.error_line` checks that contract once for all
the CLI tests.
"""

from __future__ import annotations

import logging
import runpy
import sys
from pathlib import Path
from typing import final

import pytest

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


@final
class ScriptRunner:
    """Run ``python scripts/<name> *args`` in process (``runpy`` as ``__main__``: the imports
    are paid once for all cases of a test module)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]):
        self._monkeypatch = monkeypatch
        self._capsys = capsys

    def __call__(self, script: str, *args: str) -> tuple[int, str, str]:
        """Exit status (0 when the script returns), stdout and stderr.

        The root logger's handlers are restored afterwards: Hydra's job logging writes to
        this test's captured streams, which are closed once the test ends (a later log line
        would print a "Logging error" traceback into another test's stderr).
        """
        path = SCRIPTS / script
        self._monkeypatch.setattr(sys, "argv", [str(path), *args])
        self._monkeypatch.syspath_prepend(str(SCRIPTS))  # as `python scripts/x.py` has it
        root = logging.getLogger()
        handlers, level = list(root.handlers), root.level
        code = 0
        try:
            runpy.run_path(str(path), run_name="__main__")
        except SystemExit as exc:
            code = exc.code or 0
        finally:
            for handler in root.handlers:
                if handler not in handlers:
                    handler.close()
            root.handlers[:] = handlers
            root.setLevel(level)
        out = self._capsys.readouterr()
        return code, out.out, out.err

    def error_line(self, script: str, *args: str) -> str:
        """Run a script on bad input; assert exit status 2 and one ``error: `` line on stderr
        without a traceback; return that line."""
        code, out, err = self(script, *args)
        assert code == 2, (code, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), err
        assert "Traceback" not in err, err
        return lines[0]


@pytest.fixture
def run_script(monkeypatch: pytest.MonkeyPatch,
               capsys: pytest.CaptureFixture[str]) -> ScriptRunner:
    """A :class:`ScriptRunner` bound to this test's monkeypatch and capsys."""
    return ScriptRunner(monkeypatch, capsys)
