"""argparse value types shared by the commands: a bad value is a usage error (exit 2) naming it."""
from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager

from tracelab.engine.grounding_limit import grounding_limit
from tracelab.engine.kernel_names import KERNELS as ENGINE_KERNELS  # noqa: F401  (--kernel's choices, for the commands)
from tracelab.engine.safe_files import parse_byte_size


def integer(text: str) -> int:
    """An integer, also written as the field writes budgets: 100000, 100_000, 1e5, 1.5e3. The value must be a
    whole number: 1.5 is refused, not rounded."""
    try:
        return int(text)
    except ValueError:
        pass
    # deferred: only a budget written 1e5 needs decimal; every command starts through this module
    from decimal import Decimal, InvalidOperation
    try:
        value = Decimal(text.strip().replace("_", ""))
    except InvalidOperation:
        value = None
    if value is None or not value.is_finite() or value != value.to_integral_value() or abs(value) > 10 ** 18:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r} (e.g. 100000 or 1e5)")
    return int(value)




_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def boolean(text: str) -> bool:
    """true/false, yes/no, on/off, 1/0 (CleanRL's `--torch-deterministic False`)."""
    if text.strip().lower() in _TRUE + _FALSE:
        return text.strip().lower() in _TRUE
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


def non_negative_int(text: str) -> int:
    v = integer(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {v}")
    return v


def positive_int(text: str) -> int:
    v = integer(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v




def byte_size(text: str) -> int:
    """A number of bytes: 2000000000, 500M, 8G, 1.5T (binary units; a trailing B or iB is allowed)."""
    try:
        return parse_byte_size(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_max_groundings(parser: argparse.ArgumentParser) -> None:
    """--max-groundings, for the commands that ground a rule program (applied by `grounding_limit_of`)."""
    parser.add_argument("--max-groundings", dest="max_groundings", type=positive_int, metavar="N",
                        default=argparse.SUPPRESS,
                        help="refuse a rule program that could make more than N groundings, before grounding "
                             "it (default: from this machine's memory; docs/language.md)")


@contextmanager
def grounding_limit_of(args: argparse.Namespace) -> Iterator[None]:
    """Inside: the engines a command builds (directly, or in its envs, trainers and benches) allow
    `--max-groundings` groundings, when the command has the flag and it was given."""
    n = getattr(args, "max_groundings", None)
    if n is None:
        yield
        return
    with grounding_limit(n):
        yield
