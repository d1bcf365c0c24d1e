"""`tracelab reason`: run any rule program on a graph and print its trace and final interpretation, or
record it into a run of the trace store (`--run DIR`) for the reading commands and the viewers."""
from __future__ import annotations

import argparse
import itertools
import json
import os
import shlex
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.commands._progress import compiling_engine
from tracelab.commands._recording import read_for_hints
from tracelab.engine import ProgramError, parse_literal
from tracelab.engine.errors import is_interrupt
from tracelab.engine.program import constant_text
from tracelab.errors import UserError, store_errors
from tracelab.reasoning import EpisodeRun, load_inputs, open_reasoning_run, plan_episodes
from tracelab.reasoning_reference import reference_fits, reference_reasoning

# deferred: the store (DuckDB), with --run only, and the PyReason trace writer (numba), with --pyreason-trace only:
# a small program printed as it reasons runs on the reference evaluator without them


def run(args: argparse.Namespace) -> int:
    """Program errors (located), unreadable files, InconsistencyError and FixpointError (naming the atom,
    the time and the rules and facts with their file:line) are raised for main() to report; with --run
    the run keeps what was reasoned until then (status failed)."""
    args.kernel_chosen, args.kernel = args.kernel is not None, args.kernel or "auto"

    if args.persistent and args.dialect != "pyreason":
        raise UserError("--persistent belongs to --dialect pyreason (tracelab programs say %timesteps)")
    if args.run is not None and args.no_trace:
        raise UserError("--run records the trace and --no-trace drops it: give one of them")
    if args.run is not None:
        from tracelab.store.layout import check_new_run_dir
        check_new_run_dir(Path(args.run))
    inputs = load_inputs(args.program, dialect=args.dialect, graph_file=args.graph, fact_files=args.facts,
                         fact_tables=args.facts_table, persistent=args.persistent)
    for w in inputs.program.warnings:
        print(w, file=sys.stderr)
    for q in args.query:
        try:
            parse_literal(q)
        except ProgramError as e:
            raise UserError(f"--query {q!r}: {e.message}") from e
    try:
        plans = plan_episodes(inputs, args.repeat)
    except ValueError as e:
        raise UserError(str(e)) from e
    if args.run is None:
        docs = [_reason(args, inputs, plan, None, several=len(plans) > 1) for plan in plans]
        if args.json:
            json.dump(docs[0] if len(docs) == 1 else {"episodes": docs}, sys.stdout, indent=1)
            print()
        return 0
    return _record(args, inputs, plans)


def _record(args: argparse.Namespace, inputs: Any, plans: list[Any]) -> int:
    """The reasoning into a new run of the store (tracelab.store.reasoning): the trace goes there."""
    from tracelab.store.reasoning import ReasoningRecorder

    run_dir = Path(args.run)
    settings = {"steps": args.steps, "repeat": args.repeat, "kernel": args.kernel, "persistent": args.persistent}
    command = " ".join(shlex.quote(a) for a in ["tracelab", *args.argv])
    try:
        with store_errors():  # another process took the directory since the check: a RuntimeError
            writer = open_reasoning_run(run_dir, inputs, command, settings)
    except OSError as e:
        raise UserError(f"cannot create the run directory {run_dir}: {e.strerror or e}") from e
    recorder = ReasoningRecorder(writer, episodes=len(plans))
    try:
        docs = [_reason(args, inputs, plan, recorder, several=len(plans) > 1) for plan in plans]
    except BaseException as e:
        writer.close(status="interrupted" if is_interrupt(e) else "failed")  # flushes what was reasoned
        raise
    writer.close()
    if args.json:
        json.dump({"run": str(run_dir), "episodes": docs}, sys.stdout, indent=1)
        print()
        return 0
    print(f"recorded {len(docs)} episode{'s' if len(docs) != 1 else ''} ({recorder.rows:,} changes) into "
          f"{run_dir}/: " + ", ".join(f"episode {d['episode']} {d['outcome']} after {d['steps']} steps"
                                      for d in docs[:3]) + (", ..." if len(docs) > 3 else ""))
    _what_to_open(run_dir, docs[0]["episode"])
    return 0


def _reason(args: argparse.Namespace, inputs: Any, plan: Any, recorder: Any, several: bool) -> dict[str, Any]:
    """One episode: build, step, print (or record) its trace and answer the queries; returns what --json
    prints of it."""
    if several and not args.json and recorder is None:
        print(f"episode {plan.episode}:")
    if not several and _reference_serves(args, inputs, plan, recorder):
        doc = _reason_by_reference(args, inputs)
        if doc is not None:
            return doc
    printing = recorder is None and not args.no_trace
    pr_trace = None
    busy = "grounding the program…" if args.kernel != "compiled" else \
        "grounding; compiling the program's own kernel unless cached (about a minute the first time)…"
    with compiling_engine(busy=busy, phase="reason-large"):  # the first step compiles (cold cache) and grounds
        episode = EpisodeRun(inputs, plan, trace=printing or args.pyreason_trace is not None, kernel=args.kernel,
                             recorder=recorder)
        engine = episode.engine
        if args.pyreason_trace is not None:
            from tracelab.pyreason.trace_csv import PyReasonTrace
            pr_trace = PyReasonTrace(engine, inputs.names, inputs.graph_facts)
        stepper = episode.steps(args.steps, rows_each_step=printing or pr_trace is not None)
        first = next(stepper)
    passes = 0
    answers: list[dict[str, object]] = []
    changes: list[dict[str, object]] = []  # --json only: text output prints each step's rows as it goes
    header = False
    for t, rows in itertools.chain([first], stepper):
        if args.query and (args.query_at == "each" or t == args.steps - 1):
            answers += [{"t": t, "query": q, "bindings": b, "bound": list(bound)}
                        for q in args.query for b, bound in engine.match(q)]
        if rows is None:
            continue
        if pr_trace is not None:
            pr_trace.add(rows, passes)
            passes = int(engine.stats["passes"][0])
        if not printing:
            continue
        step_changes = _changes(engine, rows)
        if args.json:
            changes.extend(step_changes)
            continue
        header = _print_changes(step_changes, header)
    outcome = episode.finish()
    if pr_trace is not None:
        target = args.pyreason_trace if not several else os.path.join(args.pyreason_trace, f"episode-{plan.episode}")
        for path in pr_trace.write(target):
            print(f"wrote {path}", file=sys.stderr)
    stats = {k: int(np.sum(v)) for k, v in engine.stats.items()}
    stats["evaluator"] = "compiled"  # which ran: the engine's kernels (or the reference evaluator's, below)
    if recorder is not None:
        _print_answers(args, answers)
        return {"episode": plan.episode, "steps": args.steps, "outcome": outcome, "queries": answers,
                "stats": stats}
    final = engine.interpretation(0)
    if args.json:
        doc = {"steps": args.steps, "changes": changes,
               "interpretation": {k: list(v) for k, v in final.items()}, "queries": answers, "stats": stats}
        return {"episode": plan.episode, **doc, "outcome": outcome} if several else doc
    if header:
        print()
    if args.query:
        _print_answers(args, answers)
        return {}
    _print_final(args, final)
    return {}


def _reference_serves(args: argparse.Namespace, inputs: Any, plan: Any, recorder: Any) -> bool:
    """A small program printed as it reasons, and nothing the reference evaluator does not do (a run, a
    graph or fact table, PyReason's trace, queries, a chosen kernel): no need to load the compiled engine."""
    return (recorder is None and not args.kernel_chosen and args.pyreason_trace is None and not args.query
            and inputs.graph is None and plan.graph is None and reference_fits(inputs.program, args.steps))


def _reason_by_reference(args: argparse.Namespace, inputs: Any) -> dict[str, Any] | None:
    """The episode on the reference evaluator, printed as the compiled engine's is; None (nothing printed)
    when it cannot finish it: the compiled engine then runs it and says why in its own words."""
    try:
        steps, final = reference_reasoning(inputs.program, args.steps)
    except Exception:  # noqa: BLE001 - no fixpoint, an inconsistency: the engine's error names the rules
        return None
    changes = [c for step in steps for c in step]
    stats = {"evaluator": "reference", "changes": len(changes)}
    if args.json:
        return {"steps": args.steps, "changes": [] if args.no_trace else changes,
                "interpretation": {k: list(v) for k, v in final.items()}, "queries": [], "stats": stats}
    if not args.no_trace and _print_changes(changes, False):
        print()
    _print_final(args, final)
    return {}


def _print_changes(changes: list[dict[str, Any]], header: bool) -> bool:
    """Trace rows as a table (its header first unless `header` says it is printed); whether it is now."""
    for c in changes:
        if not header:
            print(f"{'t':>4} {'pass':>4}  {'atom':<32} {'old':<11} {'new':<11} cause")
            header = True
        print(f"{c['t']:>4} {c['pass']:>4}  {c['atom']:<32} {_fmt(c['old']):<11} {_fmt(c['new']):<11} "
              f"{c['cause']}{'  ' + c['grounding'] if c['grounding'] else ''}")
    return header


def _print_final(args: argparse.Namespace, final: dict[str, Any]) -> None:
    print(f"final interpretation at t={args.steps - 1}:")
    for atom, bound in sorted(final.items()):
        print(f"  {atom}: {_fmt(bound)}")


def _print_answers(args: argparse.Namespace, answers: list[dict[str, Any]]) -> None:
    if args.json:
        return
    for q in args.query:
        for t in range(args.steps) if args.query_at == "each" else [args.steps - 1]:
            hits = [a for a in answers if a["t"] == t and a["query"] == q]
            print(f"t={t} {q}: {len(hits)} answer{'s' if len(hits) != 1 else ''}")
            for a in hits:
                bind = ", ".join(f"{v}={constant_text(x)}" for v, x in a["bindings"].items()) or "(ground)"
                print(f"  {bind}  {_fmt(a['bound'])}")


def _what_to_open(run_dir: Path, episode: int) -> None:
    """Commands to read the run, with an atom the reasoning set true last as the example."""
    row = read_for_hints(run_dir, lambda con: con.execute(
        "SELECT a.label, a.arg0, a.arg1, c.t FROM raw.changes c JOIN atoms a ON a.atom = c.atom "
        "WHERE c.episode = ? AND c.cause_kind = 2 AND c.new_lower = 1 ORDER BY c.seq DESC LIMIT 1",
        [episode]).fetchall())
    run = shlex.quote(str(run_dir))
    hints = [(f"tracelab trace {run} --episode {episode} --limit 20", "the trace table")]
    if row:
        label, *args, t = row[0]
        atom = f"{label}({','.join(constant_text(a) for a in args if a is not None)})"
        hints.append((f"tracelab why {run} {shlex.quote(atom)} --episode {episode} --at {t}", "why is it true?"))
    hints += [(f"tracelab sql {run} --query rule_coverage", "which rules fired"),
              (f"tracelab show {run}", "the run, its program and counts")]
    width = max(len(command) for command, _ in hints)
    print("what to open:")
    for command, what in hints:
        print(f"  {command:<{width}}   # {what}")


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
