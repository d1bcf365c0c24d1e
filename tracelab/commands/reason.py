"""`tracelab reason`: run any rule program on a graph and print its trace and final interpretation."""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np

from tracelab.commands._args import ENGINE_KERNELS, add_max_groundings, positive_int
from tracelab.errors import UserError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reason", help="run a rule program and print its trace and final interpretation")
    p.add_argument("program", nargs="+", help="rule files (merged into one program)")
    p.add_argument("--dialect", choices=("tracelab", "pyreason"), default="tracelab",
                   help="the language of the rule, fact and graph files: tracelab's (default) or PyReason's "
                        "(rules .txt/.csv/.json, facts .csv/.json, its GraphML mapping; docs/pyreason.md)")
    p.add_argument("--graph", help="a GraphML graph (node/edge attributes become static facts)")
    p.add_argument("--facts", action="append", default=[], help="a file of facts (rule syntax, or PyReason's "
                                                                "fact files with --dialect pyreason)")
    p.add_argument("--facts-table", action="append", default=[], metavar="TABLE",
                   help="a Parquet or CSV table of facts (columns atom, lower, upper, start, end, static)")
    p.add_argument("--steps", type=positive_int, required=True, help="timesteps to run (at least 1)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--no-trace", action="store_true", help="print the final interpretation only")
    p.add_argument("--query", action="append", default=[], metavar="LITERAL",
                   help='print the bindings and bounds where a literal holds, e.g. "infected(X)" or '
                        '"link(a,Y):[0.5,1]" (repeatable; replaces the final interpretation)')
    p.add_argument("--query-at", choices=("end", "each"), default="end",
                   help="answer the queries after the last step (default) or after each step")
    p.add_argument("--persistent", action="store_true",
                   help="--dialect pyreason: PyReason's persistent=True (atoms keep their bounds between steps)")
    p.add_argument("--pyreason-trace", metavar="DIR",
                   help="also write the rule trace in PyReason's CSV layout (rule_trace_nodes_*.csv, "
                        "rule_trace_edges_*.csv) into DIR")
    p.add_argument("--kernel", choices=ENGINE_KERNELS, default="auto",
                   help="the engine's kernel (default auto; compiled: the program's own, docs/engine-api.md)")
    add_max_groundings(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Program errors (located), unreadable files, InconsistencyError and FixpointError (naming the atom,
    the time and the rules and facts with their file:line) are raised for main() to report."""
    from tracelab.commands._progress import compiling_engine
    from tracelab.engine import (
        Engine,
        ProgramError,
        check_program,
        load_fact_table,
        load_graphml,
        load_program,
        parse_literal,
    )
    from tracelab.engine.program import constant_text

    names = None
    if args.dialect == "pyreason":
        from tracelab.pyreason import load_pyreason
        translated = load_pyreason(args.program, args.facts, args.graph, persistent=args.persistent)
        program, graph, names = translated.program, translated.graph, translated.names
    else:
        if args.persistent:
            raise UserError("--persistent belongs to --dialect pyreason (tracelab programs say %timesteps)")
        program = load_program(*args.program, *args.facts)
        graph = load_graphml(args.graph) if args.graph else None
    graph_facts = graph.n_facts if graph is not None else 0
    for table in args.facts_table:
        facts = load_fact_table(table)
        graph = facts if graph is None else graph.concat(facts)
    if graph is not None:  # what the graph sets is set: no "never set" warnings, arities must agree
        check_program(program, graph.predicates())
    for w in program.warnings:
        print(w, file=sys.stderr)
    for q in args.query:
        try:
            parse_literal(q)
        except ProgramError as e:
            raise UserError(f"--query {q!r}: {e.message}") from e
    busy = "grounding the program…" if args.kernel != "compiled" else \
        "grounding; compiling the program's own kernel unless cached (about a minute the first time)…"
    with compiling_engine(busy=busy):  # the first step compiles (cold cache) and grounds
        engine = Engine(program, graph, trace=not args.no_trace or args.pyreason_trace is not None,
                        kernel=args.kernel)
        pr_trace = None
        if args.pyreason_trace is not None:
            from tracelab.pyreason.trace_csv import PyReasonTrace
            pr_trace = PyReasonTrace(engine, names, graph_facts)
        passes = 0
        engine.step()
    answers: list[dict[str, object]] = []
    changes: list[dict[str, object]] = []  # --json only: text output prints each step's rows as it goes
    header = False
    for t in range(args.steps):
        if t:
            engine.step()
        if args.query and (args.query_at == "each" or t == args.steps - 1):
            answers += [{"t": t, "query": q, "bindings": b, "bound": list(bound)}
                        for q in args.query for b, bound in engine.match(q)]
        rows = engine.take_trace()
        if pr_trace is not None:
            pr_trace.add(rows, passes)
            passes = int(engine.stats["passes"][0])
        if args.no_trace:
            continue
        step_changes = _changes(engine, rows)
        if args.json:
            changes.extend(step_changes)
            continue
        for c in step_changes:
            if not header:
                print(f"{'t':>4} {'pass':>4}  {'atom':<32} {'old':<11} {'new':<11} cause")
                header = True
            print(f"{c['t']:>4} {c['pass']:>4}  {c['atom']:<32} {_fmt(c['old']):<11} {_fmt(c['new']):<11} "
                  f"{c['cause']}{'  ' + c['grounding'] if c['grounding'] else ''}")
    if pr_trace is not None:
        for path in pr_trace.write(args.pyreason_trace):
            print(f"wrote {path}", file=sys.stderr)
    final = engine.interpretation(0)
    if args.json:
        json.dump({"steps": args.steps, "changes": changes,
                   "interpretation": {k: list(v) for k, v in final.items()}, "queries": answers,
                   "stats": {k: int(np.sum(v)) for k, v in engine.stats.items()}}, sys.stdout, indent=1)
        print()
        return 0
    if header:
        print()
    if args.query:
        for q in args.query:
            for t in range(args.steps) if args.query_at == "each" else [args.steps - 1]:
                hits = [a for a in answers if a["t"] == t and a["query"] == q]
                print(f"t={t} {q}: {len(hits)} answer{'s' if len(hits) != 1 else ''}")
                for a in hits:
                    bind = ", ".join(f"{v}={constant_text(x)}" for v, x in a["bindings"].items()) or "(ground)"
                    print(f"  {bind}  {_fmt(a['bound'])}")
        return 0
    print(f"final interpretation at t={args.steps - 1}:")
    for atom, bound in sorted(final.items()):
        print(f"  {atom}: {_fmt(bound)}")
    return 0


def _changes(eng: Any, rows: dict[str, np.ndarray]) -> Iterator[dict[str, Any]]:
    """One step's trace rows (of Engine `eng`) as dicts with names (atoms, causes, groundings), one at a
    time (a million-fact graph writes a million rows at t = 0)."""
    n = len(rows["t"])
    for lo in range(0, n, 65_536):  # Python objects for one block of rows at a time
        cols = {k: v[lo:lo + 65_536].tolist() for k, v in rows.items()}
        yield from _named(eng, cols)


def _named(eng: Any, cols: dict[str, list[Any]]) -> Iterator[dict[str, Any]]:
    for i in range(len(cols["t"])):
        yield {"t": cols["t"][i], "pass": cols["pass_no"][i], "atom": eng.atom_text(cols["atom"][i]),
               "old": [cols["old_lower"][i], cols["old_upper"][i]],
               "new": [cols["new_lower"][i], cols["new_upper"][i]],
               "cause": eng.cause_name(cols["cause_kind"][i], cols["cause_id"][i]),
               "grounding": eng.grounding_text(cols["grounding"][i])}


def _fmt(b: list[float] | tuple[float, float]) -> str:
    return f"[{b[0]:g},{b[1]:g}]"
