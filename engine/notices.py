"""The library's notices. The library (engine, store, envs, train) prints nothing: a module with something to
report logs it to its `tracelab.*` logger, made by `library_logger`, and an application shows them as it
likes (the CLI: one line each on stderr, tracelab/commands/_notices.py, through `showing_notices`).

`logging` (with traceback, string and the rest) is imported by the first module that makes a logger, not
by tracelab's import: a command that reports nothing (every reading command) does not load it. Outside a
`showing_notices` block the `tracelab` logger's handler swallows the records (as a NullHandler: Python
would otherwise print an unconfigured logger's warnings itself), and they reach whatever logging the
application configured."""
from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import logging

LIBRARY_LOGGER = "tracelab"
# write(is_warning, message) of each showing_notices block still open, innermost last
_writers: list[Callable[[bool, str], None]] = []
_state: dict[str, Any] = {}   # "level": the `tracelab` logger's level outside the blocks, once it is made


def library_logger(name: str) -> logging.Logger:
    """The logger of the library module `name` (its `__name__`, under `tracelab`)."""
    import logging
    if "level" not in _state:
        _state["level"] = logging.getLogger(LIBRARY_LOGGER).level
        logging.getLogger(LIBRARY_LOGGER).addHandler(_handler_class()())
        _set_level()
    return logging.getLogger(name)


def _set_level() -> None:
    """INFO while a block shows the notices, else what the logger had (nothing if it is not made yet)."""
    if "level" in _state:
        import logging
        logging.getLogger(LIBRARY_LOGGER).setLevel(logging.INFO if _writers else _state["level"])


@contextmanager
def showing_notices(write: Callable[[bool, str], None]) -> Iterator[None]:
    """While the block runs, each info and warning of the `tracelab` loggers is passed to
    `write(is_warning, message)`, made now or later in the block."""
    _writers.append(write)
    _set_level()
    try:
        yield
    finally:
        _writers.remove(write)
        _set_level()


def _handler_class() -> type[logging.Handler]:
    """The handler's class, made with logging imported (by the first library_logger)."""
    import logging

    class ToWriters(logging.Handler):
        """Each record to the innermost showing_notices block's writer; none outside one."""

        def emit(self, record: logging.LogRecord) -> None:
            if not _writers:
                return
            try:
                _writers[-1](record.levelno >= logging.WARNING, record.getMessage())
            except Exception:  # logging's contract: a handler never raises into the code that logged
                self.handleError(record)

    return ToWriters
