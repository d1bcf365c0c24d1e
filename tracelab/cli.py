"""tracelab: a semantic simulation proxy for reinforcement learning that explains itself.

The `tracelab` command. Each subcommand lives in its own module under tracelab/commands/ and exposes
`register(subparsers)`; modules are imported lazily so that `tracelab --help` stays fast (no torch)."""
from __future__ import annotations

import argparse
import importlib
import sys

# One line per subcommand module; each module adds its own parsers and sets `func` on them.
COMMAND_MODULES = [
    "tracelab.commands.play", "tracelab.commands.reason",
    "tracelab.commands.trace", "tracelab.commands.why", "tracelab.commands.why_not",
    "tracelab.commands.sql", "tracelab.commands.diff", "tracelab.commands.seal",
    "tracelab.commands.bench", "tracelab.commands.train", "tracelab.commands.eval",
    "tracelab.commands.experiment",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tracelab", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
