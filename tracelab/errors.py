"""The CLI's one error convention: what counts as a user error, and its one-line message.

Commands raise; `tracelab.cli.main` prints `tracelab: error: <message>` on stderr and exits 1 for every
error `user_error_message` recognises, and lets anything else (a bug) show its traceback. This module
imports nothing heavy: the error classes of the engine, the scenarios and DuckDB are looked up only if
their modules were imported, since an error of a module never imported cannot have been raised."""
from __future__ import annotations

import re
import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager


class UserError(ValueError):
    """A mistake in what the user asked for (a bad value, a run that does not exist, ...)."""


SUGGESTION_CANDIDATES = 20_000  # names compared for a did-you-mean (difflib is linear in them)
SUGGESTION_LENGTH = 200  # and quadratic in a name's length: a longer name gets no suggestion


def close_names(name: str, known: Iterable[str], n: int = 5) -> list[str]:
    """The known names closest to a mistyped `name`, best first (none close: []), for `did you mean`;
    bounded in cost whatever a stranger's file names."""
    if len(name) > SUGGESTION_LENGTH:
        return []
    candidates = [k for _, k in zip(range(SUGGESTION_CANDIDATES), known) if len(k) <= SUGGESTION_LENGTH]
    import difflib  # deferred: only a mistyped name needs it (every command imports this module)
    return difflib.get_close_matches(name, candidates, n=n)


# (module, class names): user errors of other parts of tracelab and of DuckDB
_FOREIGN = (
    ("tracelab.engine.errors", ("ProgramError", "InconsistencyError", "FixpointError")),
    ("tracelab.engine.safe_files", ("FileRefused",)),
    ("tracelab.engine.duckdb_limits", ("SandboxSettingError",)),  # $TRACELAB_QUERY_MEMORY, where DuckDB reads
    ("tracelab.game.scenario", ("ScenarioError",)),
    ("tracelab.store.sandbox", ("QueryRefused",)),  # wherever a query's rows are read
    ("duckdb", ("Error",)),
)


def _foreign_user_errors() -> tuple[type[BaseException], ...]:
    out: list[type[BaseException]] = []
    for module, names in _FOREIGN:
        m = sys.modules.get(module)
        if m is not None:
            out.extend(getattr(m, n) for n in names if hasattr(m, n))
    return tuple(out)


_QUERY_LINE = re.compile(r"LINE (\d+): ")


def one_line(text: str) -> str:
    """A message on one line. DuckDB's echo of the query (`LINE 2: ...` and a caret line under it)
    becomes `(at line 2, column 3 of the query)`."""
    lines = text.splitlines()
    kept: list[str] = []
    for i, ln in enumerate(lines):
        m = _QUERY_LINE.match(ln)
        if m:
            caret = lines[i + 1] if i + 1 < len(lines) else ""
            column = caret.find("^") - m.end() + 1
            where = f"line {m.group(1)}, column {column}" if column > 0 else f"line {m.group(1)}"
            kept.append(f"(at {where} of the query)")
        elif ln.strip() and set(ln.strip()) != {"^"}:
            kept.append(ln.strip())
    return " ".join(kept)


# The optional packages (pyproject.toml's extras): the extra that installs each, and what needs it. The
# main job's `pip install -e .` leaves them out (torch and rerun-sdk are 1.3 GB of a 1.9 GB install).
OPTIONAL_PACKAGES = {
    "torch": ("train", "training and policies: train, eval, play --policy, whatif --policy"),
    "rerun": ("replay", "tracelab replay"),
    "stable_baselines3": ("sb3", "Stable-Baselines3 trainings"),
    "ray": ("ray", "experiment --ray, sweep"),
    "tensorboard": ("tensorboard", "TensorBoard logs"),
    "matplotlib": ("experiments", "the experiment plots"),
    "pandas": ("pyreason", "PyReason's DataFrames"),
    "networkx": ("pyreason", "PyReason's graphs"),
}


def missing_package_message(e: ModuleNotFoundError) -> str | None:
    """`<package> is not installed (needed for ...): pip install 'tracelab[extra]'` for an optional
    package, else None."""
    package = (e.name or "").partition(".")[0]
    if package not in OPTIONAL_PACKAGES:
        return None
    extra, needed_for = OPTIONAL_PACKAGES[package]
    return f"{package} is not installed (needed for {needed_for}): pip install 'tracelab[{extra}]'"


def user_error_message(e: BaseException) -> str | None:
    """The one-line message of a user error, or None for an error that is not one (a bug)."""
    if isinstance(e, UserError):
        return one_line(str(e))
    if isinstance(e, ModuleNotFoundError):
        return missing_package_message(e)
    engine_errors = sys.modules.get("tracelab.engine.errors")
    if engine_errors is not None and isinstance(e, engine_errors.ProgramError):
        return f"{e.location}: {one_line(e.message)}"  # the source line and caret would make it 3 lines
    if isinstance(e, UnicodeDecodeError):
        return f"not UTF-8 text: byte 0x{e.object[e.start]:02x} at offset {e.start} cannot be decoded"
    if isinstance(e, OSError) and not isinstance(e, BrokenPipeError):
        if e.strerror and e.filename is not None:
            return f"{e.filename}: {e.strerror}"
        return one_line(str(e))
    sandbox = sys.modules.get("tracelab.store.sandbox")
    if sandbox is not None and isinstance(e, sandbox.duckdb.OutOfMemoryException):
        return sandbox.out_of_memory_message(e)  # names the limit and how to raise it
    if isinstance(e, _foreign_user_errors()):
        return one_line(str(e))
    return None


@contextmanager
def store_errors() -> Iterator[None]:
    """Inside: the trace store's KeyError / ValueError / RuntimeError (a run, an episode, a query or a
    parameter that does not exist, a run still being written) become UserErrors. The store raises these
    for what the user named; everything else stays a bug."""
    try:
        yield
    except UserError:
        raise
    except (KeyError, ValueError, RuntimeError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
        raise UserError(str(msg)) from e
