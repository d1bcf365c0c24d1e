"""The check every located-error test makes: a ProgramError names FILE:LINE:COLUMN and says what."""
from __future__ import annotations

from tracelab.engine import ProgramError


def assert_located(error: ProgramError, file: str, line: int, column: int, fragment: str) -> None:
    """`error` is at `file`:`line`:`column` and its message holds `fragment`."""
    assert (error.file, error.line, error.column) == (file, line, column), str(error)
    assert fragment in error.message, error.message
