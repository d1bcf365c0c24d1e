"""tracelab: a semantic simulation proxy for reinforcement learning that explains itself.

The `tracelab` command. The parser is built from the command table (tracelab/commands/_table.py: every
command's name, help and arguments), which imports no command module: `tracelab --help` loads no heavy
package, and a command builds its own parser only. Each command lives in its own module under
tracelab/commands/, named after it (`why-not`: commands/why_not.py), imported when the command runs; its
`run(args)` does the work.

Output: everything a command prints goes through commands._output.escaped_output (control characters
escaped: a run's strings never reach the terminal as escape sequences).

Errors: commands raise, main() reports. A user error (tracelab.errors.user_error_message) is one line
`tracelab: error: ...` on stderr and exit status 1; a usage error is argparse's message and status 2; a
closed pipe (`tracelab trace ... | head`) ends quietly; anything else is a bug and keeps its traceback."""
from __future__ import annotations

import argparse
import gc
import os
import sys

from tracelab import __version__
from tracelab.commands._args import grounding_limit_of
from tracelab.commands._notices import showing_library_notices
from tracelab.commands._output import escaped_output
from tracelab.commands._table import BY_NAME, COMMANDS
from tracelab.errors import user_error_message
from tracelab.frozen_imports import import_frozen
EXIT_USER_ERROR = 1
EXIT_USAGE = 2  # argparse's status for a usage error
EXIT_BROKEN_PIPE = 141  # what a shell reports for a process ended by SIGPIPE


def command_module(command: str) -> str | None:
    """The module of a command's name (`why-not`: tracelab.commands.why_not), None for no command."""
    return BY_NAME[command].module if command in BY_NAME else None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or of `command` alone (what running it needs)."""
    parser = argparse.ArgumentParser(prog="tracelab", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"tracelab {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for c in [BY_NAME[command]] if command in BY_NAME else COMMANDS:
        c.add_to(sub)
    return parser


def _late_positionals(parser: argparse.ArgumentParser, args: argparse.Namespace, unknown: list[str]) -> list[str]:
    """Fill an optional positional (nargs="?") given after the flags: argparse matches it, empty, with the
    positionals before the first flag (`tracelab why RUN --episode 2 'dead(me)'`); what is left stays
    unknown."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[args.command]
    for action in sub._actions:
        if not unknown or unknown[0].startswith("-"):
            break
        if not action.option_strings and action.nargs == "?" and getattr(args, action.dest) is None:
            setattr(args, action.dest, unknown.pop(0))
    return unknown


def _unknown_arguments(parser: argparse.ArgumentParser, command: str, unknown: list[str]) -> int:
    """An unknown flag is a usage error of its subcommand: one line naming it, with the closest flags,
    not the usage of every subcommand (what the top-level parser would print)."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    flags = [s for a in sub._actions for s in a.option_strings if s.startswith("--")]
    flag = next((u.partition("=")[0] for u in unknown if u.startswith("-")), None)
    if flag is None:
        message = f"unexpected argument{'s' if len(unknown) > 1 else ''}: {' '.join(unknown)}"
    else:
        import difflib  # deferred: only a mistyped flag needs it
        near = difflib.get_close_matches(flag, flags, n=3)
        message = f"unknown flag {flag}" + (f"; did you mean {', '.join(near)}?" if near else "")
    print(f"tracelab {command}: error: {message} (tracelab {command} --help lists them)", file=sys.stderr)
    return EXIT_USAGE


def _silence_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so that the interpreter's final flush does not
    raise again (the recipe of Python's `signal` docs)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


def main(argv: list[str] | None = None) -> int:
    """The `tracelab` command (argv None: the process's own command line), or the command `argv` run in the
    caller's process."""
    with escaped_output():  # strings from runs, specs and rule files reach the terminal escaped
        try:
            return _main(argv)
        finally:
            # The process that runs the command line exits with the start's objects frozen: the interpreter's
            # collection at exit does not traverse them (~10 ms of CPU: DuckDB's own start pays it). A caller
            # running a command in its own process (the tests) gets its objects back into the collector's care.
            if argv is not None:
                gc.unfreeze()


def _main(argv: list[str] | None) -> int:
    given = sys.argv[1:] if argv is None else argv
    # a command's own parser when the line starts with one; else (--help, --version, a typo) all of them
    parser = build_parser(given[0] if given else None)
    args, unknown = parser.parse_known_args(argv)  # usage errors: argparse prints them and exits 2
    unknown = _late_positionals(parser, args, unknown)
    if unknown:
        return _unknown_arguments(parser, args.command, unknown)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # the command line, for runs that record it
    try:
        with grounding_limit_of(args), showing_library_notices():
            import_frozen(BY_NAME[args.command].module)   # and what it imports (DuckDB, torch, ...)
            status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here for output still buffered
        return status
    except KeyboardInterrupt as e:  # a command may say what was kept: KeyboardInterrupt("the run ... keeps ...")
        print("tracelab: interrupted" + (f": {e.args[0]}" if e.args else ""), file=sys.stderr)
        return 130
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except Exception as e:
        # deferred: the engine's error classes (its program model) cost a reading command's start-up
        from tracelab.engine.errors import is_interrupt
        if is_interrupt(e):  # Ctrl-C inside a compiled call, which numba wraps in SystemError
            print("tracelab: interrupted", file=sys.stderr)
            return 130
        message = user_error_message(e)
        if message is None:
            raise
        print(f"tracelab: error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR


if __name__ == "__main__":
    sys.exit(main())
