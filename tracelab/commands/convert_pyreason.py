"""`tracelab convert-pyreason`: write a PyReason program (its rule, fact and GraphML files) as the
equivalent tracelab program, which `tracelab reason` reads back (docs/pyreason.md)."""
from __future__ import annotations

import argparse
import sys

from tracelab.errors import UserError
from tracelab.pyreason import load_pyreason


def run(args: argparse.Namespace) -> int:
    translated = load_pyreason(args.rules, args.facts, args.graph, persistent=args.persistent, embed_graph=True)
    if args.output is None:
        sys.stdout.write(translated.text)
        return 0
    try:
        with open(args.output, "w", encoding="utf-8") as f:
            f.write(translated.text)
    except OSError as e:
        raise UserError(f"cannot write {args.output}: {e.strerror}") from None
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
