"""`tracelab bench`: speed and memory measured by benchmarks (docs/benchmarks.md), never by timed
assertions in tests. `bench engine`, `bench env`, `bench store`, `bench replay`, `bench train`,
`bench tui`, `bench aggregates`, `bench reason-store`, `bench toytext`, `bench play`, `bench eval`,
`bench first-run`, `bench pyreason`, `bench cli`, `bench all` (engine, env, store, replay, train);
each takes --json, --quick (small sizes: the smoke test) and --repeats (medians and spread over that
many repeats)."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tracelab.commands._progress import on_terminal, working

SECTIONS = ("engine", "env", "store", "replay", "train")
# deferred: each section's module (tracelab.bench.*) is imported when it runs: it loads what it measures
# (numba, torch, DuckDB, rerun, textual), which the other sections do not need


def _run_section(name: str, args: argparse.Namespace) -> tuple[dict[str, Any], str]:
    if name == "engine":
        from tracelab.bench import engine
        r = engine.run(args.quick, args.repeats, args.compile_repeats, args.agents,
                       getattr(args, "graph_only", False), args.kernel)
        return r, engine.report(r)
    if name == "env":
        from tracelab.bench import env
        r = env.run(args.quick, args.repeats, args.agents, args.batch, args.kernel)
        return r, env.report(r)
    if name == "replay":
        from tracelab.bench import replay
        r = replay.run(args.quick, args.repeats)
        return r, replay.report(r)
    if name == "train":
        from tracelab.bench import train
        r = train.run(args.quick, args.repeats, args.envs, args.threads)
        return r, train.report(r)
    if name == "play":
        from tracelab.bench import play
        r = play.run(args.quick, args.repeats, args.memory)
        return r, play.report(r)
    if name == "eval":
        from tracelab.bench import eval as evaluations
        r = evaluations.run(args.quick, args.repeats, args.worlds, args.memory)
        return r, evaluations.report(r)
    if name == "aggregates":
        from tracelab.bench import aggregates
        r = aggregates.run(args.quick, args.repeats)
        return r, aggregates.report(r)
    if name == "reason-store":
        from tracelab.bench import reason_store
        r = reason_store.run(args.quick, args.repeats)
        return r, reason_store.report(r)
    if name == "toytext":
        from tracelab.bench import toytext
        r = toytext.run(args.quick, args.repeats, args.batch)
        return r, toytext.report(r)
    if name == "first-run":
        from tracelab.bench import first_run
        r = first_run.run(args.quick, args.repeats, args.fresh_venv, args.only)
        if args.write_figures:
            first_run.write_figures(r)
        return r, first_run.report(r)
    if name == "cli":
        from tracelab.bench import cli
        r = cli.run(args.quick, args.repeats, args.only)
        return r, cli.report(r)
    if name == "pyreason":
        from tracelab.bench import pyreason_compare
        if not args.pyreason_python:
            print("tracelab: bench pyreason: PyReason's side not run (give --pyreason-python PYTHON, the "
                  "interpreter of a PyReason install)", file=sys.stderr, flush=True)
        r = pyreason_compare.run(args.quick, args.repeats, args.pyreason_python, args.timeout,
                                  tuple(args.program or pyreason_compare.PROGRAMS), args.cache_dir,
                                  progress=_say_pyreason_run)
        if args.plot:
            pyreason_compare.plot(r, Path(args.plot))
        return r, pyreason_compare.report(r)
    if name == "tui":
        from tracelab.bench import tui
        r = tui.run(args.quick, args.repeats, args.rows)
        return r, tui.report(r)
    from tracelab.bench import store
    r = store.run(args.quick, args.repeats)
    return r, store.report(r)


def _say_pyreason_run(r: dict[str, Any]) -> None:
    """bench pyreason's runs as they end, one JSON line each on stderr (its RSS samples included)."""
    print("bench pyreason run: " + json.dumps(r), file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    names = SECTIONS if args.bench == "all" else (args.bench,)
    results = {}
    for name in names:
        what = f"bench {name}{' (quick)' if args.quick else ''}: measuring"
        if not on_terminal():
            print(f"{what}...", file=sys.stderr, flush=True)
        with working(f"{what}…", refresh_per_second=1):  # a slow spinner: its thread shares the cores
            result, text = _run_section(name, args)
        results[name] = result
        if not args.json:
            print(f"== bench {name} ==\n{text}\n", flush=True)
    if args.json:
        json.dump(results if args.bench == "all" else results[args.bench], sys.stdout, indent=1)
        print()
    return 0
