"""`tracelab reason`: run any rule program on a graph and print its trace and final interpretation."""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reason", help="run a rule program and print its trace and final interpretation")
    p.add_argument("program", nargs="+", help="rule files (merged into one program)")
    p.add_argument("--graph", help="a GraphML graph (node/edge attributes become static facts)")
    p.add_argument("--facts", action="append", default=[], help="a file of facts (rule syntax)")
    p.add_argument("--steps", type=int, required=True, help="timesteps to run")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--no-trace", action="store_true", help="print the final interpretation only")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tracelab.engine import Engine, ProgramError, check_program, load_graphml, load_program

    try:
        program = load_program(*args.program, *args.facts)
        graph = load_graphml(args.graph) if args.graph else None
        if graph is not None:  # what the graph sets is set: no "never set" warnings, arities must agree
            check_program(program, graph.predicates())
    except (ProgramError, OSError) as e:
        print(e, file=sys.stderr)
        return 2
    for w in program.warnings:
        print(w, file=sys.stderr)
    engine = Engine(program, graph, trace=not args.no_trace)
    engine.run(args.steps)
    rows = engine.take_trace()
    changes = [
        {"t": int(rows["t"][i]), "pass": int(rows["pass_no"][i]),
         "atom": engine.atom_text(int(rows["atom"][i])),
         "old": [float(rows["old_lower"][i]), float(rows["old_upper"][i])],
         "new": [float(rows["new_lower"][i]), float(rows["new_upper"][i])],
         "cause": engine.cause_name(int(rows["cause_kind"][i]), int(rows["cause_id"][i])),
         "grounding": engine.grounding_text(int(rows["grounding"][i]))}
        for i in range(len(rows["t"]))
    ]
    final = engine.interpretation(0)
    if args.json:
        json.dump({"steps": args.steps, "changes": changes,
                   "interpretation": {k: list(v) for k, v in final.items()},
                   "stats": {k: int(np.sum(v)) for k, v in engine.stats.items()}}, sys.stdout, indent=1)
        print()
        return 0
    if changes:
        print(f"{'t':>4} {'pass':>4}  {'atom':<32} {'old':<11} {'new':<11} cause")
        for c in changes:
            print(f"{c['t']:>4} {c['pass']:>4}  {c['atom']:<32} {_fmt(c['old']):<11} {_fmt(c['new']):<11} "
                  f"{c['cause']}{'  ' + c['grounding'] if c['grounding'] else ''}")
        print()
    print(f"final interpretation at t={args.steps - 1}:")
    for atom, bound in sorted(final.items()):
        print(f"  {atom}: {_fmt(bound)}")
    return 0


def _fmt(b: list[float] | tuple[float, float]) -> str:
    return f"[{b[0]:g},{b[1]:g}]"
