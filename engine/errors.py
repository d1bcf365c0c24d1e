"""Errors of tracelab.engine: located errors in a rule program (syntax, checks) and the engine's run-time
errors."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # an annotation only: the store's readers import these errors without the program's types
    from .program import SourceLoc


class ProgramError(Exception):
    """An error in a rule program at FILE:LINE:COL (1-based). Line 0 means "somewhere in FILE" (a program
    built in code, a graph file): the position is then left out of the message."""

    def __init__(self, message: str, file: str, line: int = 0, column: int = 0,
                 source_line: str | None = None) -> None:
        # args mirror the signature so that the exception pickles (multiprocessing workers re-raise it)
        super().__init__(message, file, line, column, source_line)
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        self.source_line = source_line

    @classmethod
    def at(cls, loc: SourceLoc | None, message: str, source_line: str | None = None) -> ProgramError:
        if loc is None:
            return cls(message, "<program>")
        return cls(message, loc.file, loc.line, loc.column, source_line)

    @property
    def location(self) -> str:
        return f"{self.file}:{self.line}:{self.column}" if self.line > 0 else self.file

    def __str__(self) -> str:
        text = f"{self.location}: error: {self.message}"
        if self.source_line is None or self.line <= 0:
            return text
        src = self.source_line.rstrip("\r\n")
        # keep tabs in the padding so that the caret lines up however the terminal expands them
        before = src[: max(self.column - 1, 0)]
        pad = "".join(c if c == "\t" else " " for c in before) + " " * (self.column - 1 - len(before))
        return f"{text}\n{src}\n{pad}^"


class RuleSyntaxError(ProgramError):
    """The text does not follow the grammar; the message says what was expected."""


class ProgramCheckError(ProgramError):
    """The program parses but breaks a rule of docs/language.md (arity, safety, bounds, windows, names)."""


class InconsistencyError(RuntimeError):
    """An inconsistent update under the `abort` policy."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class FixpointError(RuntimeError):
    """A timestep's fixpoint did not converge within max_passes / max_immediate."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


def is_interrupt(error: BaseException) -> bool:
    """Ctrl-C or SIGTERM ended the work that raised `error`. A KeyboardInterrupt that lands while numba's
    dispatcher boxes a compiled function's result comes out as SystemError("... returned a result with an
    exception set") whose cause is the KeyboardInterrupt, so the chain of causes is searched too."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        if isinstance(current, (KeyboardInterrupt, SystemExit)):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False
