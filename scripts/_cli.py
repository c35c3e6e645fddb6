"""The entry points' bad-input contract, written once: ``error: <message>`` on ONE line of
stderr and exit status 2, no traceback.

Imported by the scripts as ``from _cli import bad_input_exits`` (``python scripts/x.py`` puts
scripts/ on ``sys.path``).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager


def error_line(err: BaseException) -> str:
    """``error: <message>`` on one line (a multi-line message joined with spaces; the
    exception's type name when it has no message)."""
    text = " ".join(part for part in str(err).splitlines() if part.strip())
    return f"error: {text or type(err).__name__}"


@contextmanager
def bad_input_exits(*errors: type[BaseException]) -> Iterator[None]:
    """Turn the exceptions ``errors`` (default ``ValueError``: InputError, RecordingError,
    TraceFormatError and bad settings are ValueErrors) raised inside the block into one
    :func:`error_line` on stderr and exit status 2."""
    caught = errors or (ValueError,)
    try:
        yield
    except caught as err:
        print(error_line(err), file=sys.stderr)
        sys.exit(2)
