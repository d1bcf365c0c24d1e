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

from tracelab.commands._args import ENGINE_KERNELS, add_max_groundings, positive_int
from tracelab.commands._progress import on_terminal, working

SECTIONS = ("engine", "env", "store", "replay", "train")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks: engine compile/start-up/steps/memory, simulators and "
                                     "envs, trace store")
    what = p.add_subparsers(dest="bench", required=True)
    helps = {"engine": "compile and warm-start time, RuleSim steps/s and engine work, memory over a long run",
             "env": "RuleSim vs RefSim steps/s (one world and batched), the gymnasium envs, the goals",
             "store": "trace-store ingest rows/s, sealing, point queries",
             "replay": "tracelab replay: a 500-step 5v5 game and 100 games of 1v1 converted to .rrd",
             "train": "DQN training transitions/s end to end, the update alone, the env alone, the loop's share",
             "aggregates": "quantifiers and annotation functions: registration time, cost against plain rules",
             "tui": "the terminal UI on a 10M-row run: open, first page, scroll, jump, filter (headless)",
             "reason-store": "reason --run against reason --no-trace on a 1M-edge graph: the ratio, change "
                             "rows/s into the store, peak memory",
             "toytext": "gymnasium's toy-text games as rules (docs/worlds.md) against gymnasium's own, one world",
             "play": "tracelab play --run against bench env's traced loop (1 and 64 worlds); --memory: the "
                     "peak memory of 100 / 1,000 / 10,000 recorded episodes",
             "eval": "train's evaluation games traced into a run against the same games untraced; --memory: "
                     "a training with traced evaluations, its memory sampled every second",
             "first-run": "every first compile a user meets (play, reason, a spec's env and vector env, train) "
                          "from empty caches (a fresh install) and again warm: wall and CPU time",
             "pyreason": "PyReason against tracelab on the same scripts (examples/), import changed only: "
                         "first run from empty caches, warm runs, peak memory and memory over time",
             "cli": "the reading commands' and reason's CPU seconds on the sample runs, each beside the floor "
                    "(python importing DuckDB and running SELECT 1), with the ratios and issue 40's goals",
             "all": "engine, env, store, replay and train"}
    for name, text in helps.items():
        q = what.add_parser(name, help=text)
        q.add_argument("--json", action="store_true", help="machine-readable output")
        q.add_argument("--quick", action="store_true", help="small sizes (a smoke run, not for figures)")
        q.add_argument("--repeats", type=positive_int, default=5, help="timed repeats per figure (default 5)")
        if name in ("engine", "env", "all"):
            q.add_argument("--agents", type=_sizes, default=None,
                           help="team sizes, comma-separated (default 1,5,20; --quick: 1,2)")
        if name in ("engine", "env", "all"):
            q.add_argument("--kernel", choices=ENGINE_KERNELS, default="auto",
                           help="the RuleSim engine's kernel (default auto; compiled: `tracelab compile` first)")
        if name == "tui":
            q.add_argument("--rows", type=positive_int, default=None,
                           help="change rows of the synthetic run (default 10,000,000; --quick: 200,000)")
        if name in ("env", "all", "toytext"):
            q.add_argument("--batch", type=positive_int, default=None,
                           help="worlds of the batched runs (default 256; --quick: 16)")
        if name in ("train", "all"):
            q.add_argument("--envs", type=positive_int, default=64,
                           help="worlds of the training env (default 64, as tracelab train)")
            q.add_argument("--threads", type=positive_int, default=1, help="torch threads (default 1)")
        if name in ("engine", "all"):
            q.add_argument("--compile-repeats", type=positive_int, default=None,
                           help="first-ever compiles to time (default: min(repeats, 3); --quick: 1)")
        if name == "play":
            q.add_argument("--worlds", type=positive_int, default=64,
                           help="worlds of the batched figure (default 64; --quick: 8)")
            q.add_argument("--memory", type=_counts, nargs="?", const=[100, 1000, 10_000], default=None,
                           metavar="N,N,...", help="also the memory of recorded runs of these many episodes, "
                                                   "each in a fresh process (default 100,1000,10000)")
        if name == "eval":
            q.add_argument("--worlds", type=positive_int, default=5,
                           help="games per evaluation, one per world (default 5, as train's --trace-eval-games)")
            q.add_argument("--memory", type=positive_int, nargs="?", const=1_000_000, default=None,
                           metavar="STEPS", help="also the memory of a `tracelab train` of this many steps with "
                                                 "traced evaluations, in a fresh process (default 1,000,000)")
        if name == "first-run":
            q.add_argument("--only", action="append", default=None, metavar="PHASE",
                           help="run this phase only (repeatable): play, reason-small, reason-large, spec-env, "
                                "spec-vector-env, train")
            q.add_argument("--fresh-venv", action="store_true",
                           help="run in a new venv (--system-site-packages, the project installed without deps)")
            q.add_argument("--write-figures", action="store_true",
                           help="write the cold figures into tracelab/first_run_figures.json, which the compile "
                                "notices quote")
        if name == "cli":
            q.add_argument("--only", action="append", default=None, metavar="COMMAND",
                           help="time this command only, beside the floor (repeatable; e.g. sql, compare; start: "
                                "eval's and train's CPU before their first step)")
        if name == "pyreason":
            q.add_argument("--pyreason-python", metavar="PYTHON", default=None,
                           help="the interpreter of a PyReason install (e.g. a venv's bin/python); without "
                                "it only tracelab's side runs")
            q.add_argument("--timeout", type=positive_int, default=3600, metavar="S",
                           help="seconds before a run is stopped and reported as timed out (default 3600: "
                                "PyReason's first compile has taken 15 minutes)")
            q.add_argument("--program", choices=("hello", "spread"), action="append", default=None,
                           help="the programs to run (repeat it for several; default both: PyReason's hello "
                                "world and a spread over a 2,000-node graph)")
            q.add_argument("--cache-dir", metavar="DIR", type=Path, default=None,
                           help="keep the caches (tracelab's, and the copy of PyReason that holds its own) in "
                                "DIR, shared by the programs, instead of empty ones per program in a "
                                "temporary folder; a first run that finds them filled is marked so")
            q.add_argument("--plot", metavar="PNG", default=None,
                           help="also draw every run's memory over time into this PNG (matplotlib)")
        # the sections that build engines (toytext: the envs')
        if name not in ("store", "tui", "toytext", "first-run", "pyreason", "cli"):
            add_max_groundings(q)
        if name == "engine":
            q.add_argument("--graph-only", action="store_true",
                           help="only the big-graph section (GraphML load, build, run on 2k/20k/200k nodes)")
        q.set_defaults(func=run)


def _sizes(text: str) -> list[int]:
    sizes = _counts(text, "team sizes")
    if 1 not in sizes:
        raise argparse.ArgumentTypeError("team sizes must be >= 1 and include 1 (the 1v1 figures)")
    return sizes


def _counts(text: str, what: str = "counts") -> list[int]:
    try:
        sizes = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated {what}, got {text!r}") from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"{what} must be >= 1, got {text!r}")
    return sizes


def _run_section(name: str, args: argparse.Namespace) -> tuple[dict[str, Any], str]:
    if name == "engine":
        # deferred: each benchmark's module loads what it measures (numba, torch, DuckDB, rerun, textual)
        from tracelab.bench import engine
        r = engine.run(args.quick, args.repeats, args.compile_repeats, args.agents,
                       getattr(args, "graph_only", False), args.kernel)
        return r, engine.report(r)
    if name == "env":
        from tracelab.bench import env  # deferred: as engine's, above
        r = env.run(args.quick, args.repeats, args.agents, args.batch, args.kernel)
        return r, env.report(r)
    if name == "replay":
        from tracelab.bench import replay  # deferred: as engine's, above
        r = replay.run(args.quick, args.repeats)
        return r, replay.report(r)
    if name == "train":
        from tracelab.bench import train  # deferred: as engine's, above
        r = train.run(args.quick, args.repeats, args.envs, args.threads)
        return r, train.report(r)
    if name == "play":
        from tracelab.bench import play  # deferred: as engine's, above
        r = play.run(args.quick, args.repeats, args.worlds, args.memory)
        return r, play.report(r)
    if name == "eval":
        from tracelab.bench import eval as evaluations  # deferred: as engine's, above
        r = evaluations.run(args.quick, args.repeats, args.worlds, args.memory)
        return r, evaluations.report(r)
    if name == "aggregates":
        from tracelab.bench import aggregates  # deferred: as engine's, above
        r = aggregates.run(args.quick, args.repeats)
        return r, aggregates.report(r)
    if name == "reason-store":
        from tracelab.bench import reason_store  # deferred: as engine's, above
        r = reason_store.run(args.quick, args.repeats)
        return r, reason_store.report(r)
    if name == "toytext":
        from tracelab.bench import toytext  # deferred: as engine's, above
        r = toytext.run(args.quick, args.repeats, args.batch)
        return r, toytext.report(r)
    if name == "first-run":
        from tracelab.bench import first_run  # deferred: as engine's, above
        r = first_run.run(args.quick, args.repeats, args.fresh_venv, args.only)
        if args.write_figures:
            first_run.write_figures(r)
        return r, first_run.report(r)
    if name == "cli":
        from tracelab.bench import cli  # deferred: as engine's, above
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
        from tracelab.bench import tui  # deferred: as engine's, above
        r = tui.run(args.quick, args.repeats, args.rows)
        return r, tui.report(r)
    from tracelab.bench import store  # deferred: as engine's, above
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
