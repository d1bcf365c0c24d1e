"""The command line's table: every command's name, help and arguments, read by tracelab/cli.py to build
the parser of `tracelab --help` or of the one command invoked, without importing any command module.
A command's module (tracelab/commands/<name>.py, `why-not`: why_not.py) is imported when the command runs,
and only then: it imports what it uses at its top, and its `run(args)` does the work.

A new command: its arguments function here, its line in COMMANDS, its module with `run(args)`. A value
type or a default a command's arguments need lives here or in commands/_args.py, never in a module that
loads a heavy package (tests/test_import_layers.py: `tracelab --help` loads none)."""
from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tracelab.commands._args import (
    ENGINE_KERNELS,
    add_max_groundings,
    boolean,
    byte_size,
    integer,
    non_negative_int,
    positive_int,
)
from tracelab.commands._output import add_format_options, add_paging_options

# deferred: train's and sweep's arguments come from tracelab.train.config and .sweep_spec (they load numpy),
# imported in _train and _sweep when their parser is built: a reading command's start-up does not pay for them

# experiment's choices: the keys of tracelab.train.experiments.definitions.EXPERIMENTS (which loads the
# trainers), held equal by tests/test_cli_conventions.py
EXPERIMENT_NAMES = ("1v1-base", "5v5-base", "portability", "markov-vs-nonmarkov", "markov-vs-nonmarkov-every-step",
                    "reward-shaping", "trap-corridor")
RULES_SHOWN = 40  # show's rules without --all-rules; the rest: `tracelab sql RUN "SELECT * FROM rules"`


class Command:
    """A command of the table: its name, the function that adds its arguments to its parser, its help
    (the line `tracelab --help` lists), and add_parser's other options (usage, description, ...)."""

    def __init__(self, name: str, arguments: Callable[[argparse.ArgumentParser], None], help: str,
                 **options: Any) -> None:
        self.name, self.arguments, self.help, self.options = name, arguments, help, options

    @property
    def module(self) -> str:
        """The module that runs it: `why-not`'s is tracelab.commands.why_not."""
        return "tracelab.commands." + self.name.replace("-", "_")

    def add_to(self, sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
        p = sub.add_parser(self.name, help=self.help, **self.options)
        self.arguments(p)
        p.set_defaults(func=_runner(self.module))
        return p


def _runner(module: str) -> Callable[[argparse.Namespace], int]:
    """`func` of a command's parser: imports the command's module when the command runs, and runs it."""
    def run(args: argparse.Namespace) -> int:
        return importlib.import_module(module).run(args)
    return run


def team_sizes(text: str) -> list[int]:
    """bench's --agents: comma-separated team sizes, 1 among them."""
    sizes = counts(text, "team sizes")
    if 1 not in sizes:
        raise argparse.ArgumentTypeError("team sizes must be >= 1 and include 1 (the 1v1 figures)")
    return sizes


def counts(text: str, what: str = "counts") -> list[int]:
    """Comma-separated counts, each at least 1."""
    try:
        sizes = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated {what}, got {text!r}") from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"{what} must be >= 1, got {text!r}")
    return sizes


def run_name(text: str) -> str:
    """train's --exp-name: a name, not a path (the run goes under runs/)."""
    if not text or "/" in text or "\\" in text or text in (".", ".."):
        raise argparse.ArgumentTypeError(f"expected a name without '/', got {text!r} (--run takes a path)")
    return text


def _play(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", default=None,
                   help="a war game scenario: a built-in name (base, advanced, nonmarkov) or a scenario .toml "
                        "file, played through its spec in rules/gridworld/ (default: base, or the scenario a "
                        "--policy PATH was trained on)")
    p.add_argument("--env", default=None, metavar="SPEC_OR_ID",
                   help="play a world declared in rules instead: a spec file or a registered id such as "
                        "tracelab/FrozenLake-v1 (docs/worlds.md)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of the --env (its spec's [params]), e.g. is_slippery=false (repeatable)")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes to play (default 5)")
    p.add_argument("--policy", default=None,
                   help="red's policy: random (default) or the path of a trained policy (e.g. RUN/policy)")
    p.add_argument("--agents", type=positive_int, default=None,
                   help="the war game: agents a team, each starting on its base (default: the scenario's)")
    p.add_argument("--opponent-p", type=float, default=None,
                   help="the war game: the opponent's probability of a move towards red's base (default 0.7)")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seed of the episodes and of the random policy (default 0)")
    p.add_argument("--kernel", choices=ENGINE_KERNELS, default="auto",
                   help="the rule engine's kernel: auto (default: counting, stepped with the world as one "
                        "compiled call), counting, lanes, or compiled (built in the background while the games "
                        "start on the counting kernel, unless `tracelab compile` built it ahead)")
    p.add_argument("--run", help="a new (or empty) run directory (default runs/play-<world>-<time>)")
    p.add_argument("--no-trace", action="store_true", help="play without recording a run")
    add_max_groundings(p)


def _reason(p: argparse.ArgumentParser) -> None:
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
    p.add_argument("--kernel", choices=ENGINE_KERNELS, default=None,
                   help="the engine's kernel (default auto, or the reference evaluator for a small program "
                        "printed as it reasons; compiled: the program's own, docs/engine-api.md)")
    add_max_groundings(p)
    p.add_argument("--run", metavar="DIR",
                   help="record the reasoning into a new (or empty) run directory of the trace store instead of "
                        "printing its trace: every change with its cause, the program, facts, atoms, groundings and "
                        "the graph's edges, for trace, why, why-not, sql, diff, show and the TUI (docs/store.md)")
    p.add_argument("--repeat", type=positive_int, default=1,
                   help="reason N times, one episode each (default 1); a --facts-table with an `episode` column "
                        "gives one episode per value instead")


def _convert_pyreason(p: argparse.ArgumentParser) -> None:
    p.add_argument("rules", nargs="+", help="PyReason rule files (.txt one rule a line, .csv, .json)")
    p.add_argument("--facts", action="append", default=[], help="PyReason fact files (.csv, .json)")
    p.add_argument("--graph", help="a GraphML graph read with PyReason's mapping; its facts are written into "
                                   "the program as static facts")
    p.add_argument("--persistent", action="store_true",
                   help="PyReason's persistent=True (default: PyReason's non-persistent timesteps)")
    p.add_argument("-o", "--output", help="the tracelab rule file to write (default: standard output)")


def _run_pyreason(p: argparse.ArgumentParser) -> None:
    p.add_argument("script", help="the PyReason script (.py)")
    p.add_argument("script_args", nargs=argparse.REMAINDER, help="the script's own arguments")


def _trace(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("--episode", "-e", type=non_negative_int, required=True, help="the episode to show")
    p.add_argument("--from", dest="t_from", type=non_negative_int, help="first timestep (default: the start)")
    p.add_argument("--to", dest="t_to", type=non_negative_int, help="last timestep (default: the end)")
    p.add_argument("--atom", action="append", default=[],
                   help="atom text or glob, e.g. 'atLoc(red-agent-1,*)' (repeatable)")
    p.add_argument("--label", action="append", default=[], help="predicate name or glob (repeatable)")
    p.add_argument("--rule", action="append", default=[],
                   help="rule name or glob, also fact:NAME, action, policy:NAME, reset (repeatable)")
    static = p.add_mutually_exclusive_group()
    static.add_argument("--static", dest="static", action="store_true", default=None,
                        help="show the rows of static facts (e.g. the map at t=0; the table hides them)")
    static.add_argument("--hide-static", dest="static", action="store_false",
                        help="hide the rows of static facts (the exports keep them otherwise)")
    add_format_options(p)
    add_paging_options(p)


def _why(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("atom", nargs="?", help="a ground atom, e.g. 'atLoc(red-agent-1,16)' (not a complement "
                                           "'~...': ask about the atom itself)")
    p.add_argument("--action", metavar="AGENT",
                   help="instead of an atom: why AGENT took its action at step --at (its policy's value of "
                        "every action, the mask, the observation it acted on, the step's reward terms)")
    p.add_argument("--episode", "-e", type=non_negative_int, required=True, help="the episode to explain")
    p.add_argument("--at", type=non_negative_int,
                   help="timestep, at most the episode's last (default: the episode's last)")
    p.add_argument("--pass", dest="pass_no", type=non_negative_int,
                   help="explain the atom's change in this pass of step --at (immediate rules cascade in "
                        "passes, so an atom may change more than once in a step; default: its bound at the "
                        "end of the step)")
    p.add_argument("--depth", type=positive_int, default=6,
                   help="how many rule firings deep to explain (default 6)")
    p.add_argument("--json", action="store_true", help="the tree as JSON")


def _why_not(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("--episode", "-e", type=non_negative_int, required=True, help="the episode to look in")
    p.add_argument("--rule", help="rule name")
    p.add_argument("--action", metavar="NAME",
                   help="instead of a rule: why --agent did not take action NAME at step --at (the mask, or "
                        "how far its value fell below the chosen action's)")
    p.add_argument("--agent", help="with --action: the agent (default: the episode's one deciding agent)")
    p.add_argument("--grounding", default="", help="variable values, e.g. A=red-agent-1,X=c3_1 "
                                                   "(unbound variables are searched)")
    p.add_argument("--at", type=non_negative_int, required=True,
                   help="the timestep the head would have changed (a rule with delay k reads its body at at-k)")
    p.add_argument("--json", action="store_true", help="the result as JSON")


def _sql(p: argparse.ArgumentParser) -> None:
    p.add_argument("words", nargs="*", metavar="RUN ... QUERY",
                   help="runs (directories, .duckdb files, names under runs/, or folders of runs), then one "
                        "SELECT statement; on several runs every view has a first column `run`")
    p.add_argument("--query", "-q", dest="saved", metavar="NAME", help="run a saved query instead")
    p.add_argument("--param", "-p", action="append", default=[], metavar="NAME=VALUE",
                   help="a saved query's parameter (repeatable)")
    p.add_argument("--list", action="store_true", help="list the saved queries and their parameters "
                                                       "(no RUN needed)")
    add_format_options(p)
    add_paging_options(p)


def _diff(p: argparse.ArgumentParser) -> None:
    p.add_argument("sides", nargs="+", metavar="RUN[:EP]",
                   help="RUN A B (one run, two episodes) or RUN_A[:EP] RUN_B[:EP] (two runs; without :EP, "
                        "the run's only episode); a run is a run directory, .duckdb file, or run name under runs/")
    p.add_argument("--json", action="store_true", help="the divergence as JSON")


def _seal(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory or run name under runs/")
    p.add_argument("--keep-parts", action="store_true", help="keep the Parquet parts afterwards")


def _bench(p: argparse.ArgumentParser) -> None:
    what = p.add_subparsers(dest="bench", required=True)
    helps = {"engine": "compile and warm-start time, the spec's steps/s and engine work, memory over a long run",
             "env": "war.toml vs RefSim steps/s (one world and batched), the gymnasium envs, the goals",
             "store": "trace-store ingest rows/s, sealing, point queries",
             "replay": "tracelab replay: a 500-step 5v5 game and 100 games of 1v1 converted to .rrd",
             "train": "DQN training transitions/s end to end, the update alone, the env alone, the loop's share",
             "aggregates": "quantifiers and annotation functions: registration time, cost against plain rules",
             "tui": "the terminal UI on a 10M-row run: open, first page, scroll, jump, filter (headless)",
             "reason-store": "reason --run against reason --no-trace on a 1M-edge graph: the ratio, change "
                             "rows/s into the store, peak memory",
             "toytext": "gymnasium's toy-text games as rules (docs/worlds.md) against gymnasium's own, one world",
             "play": "tracelab play --run against bench env's traced loop (one world); --memory: the "
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
            q.add_argument("--agents", type=team_sizes, default=None,
                           help="team sizes, comma-separated (default 1,5,20; --quick: 1,2)")
        if name in ("engine", "env", "all"):
            q.add_argument("--kernel", choices=ENGINE_KERNELS, default="auto",
                           help="the spec engine's kernel (default auto; compiled: `tracelab compile` first)")
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
            q.add_argument("--memory", type=counts, nargs="?", const=[100, 1000, 10_000], default=None,
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
                                "eval's and train's CPU before their first step; tui: the TUI's first screen)")
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


def _check(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("--repair", action="store_true",
                   help="move damaged parts to <run>/quarantine/, take them out of the manifest, and "
                        "remove temp files and parts the manifest no longer lists")


def _show(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("--all-rules", action="store_true", help=f"list every rule (default: the first {RULES_SHOWN})")
    p.add_argument("--json", action="store_true", help="everything as one JSON document")


def _replay(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--episode", "-e", type=non_negative_int, help="one episode id")
    which.add_argument("--episodes", help="episodes, e.g. 0-9 or 1,4,7-9")
    p.add_argument("--outcome", help="only episodes with this outcome (for red: win, loss, draw, truncated; "
                                     "a reasoning: converged, stopped, failed)")
    p.add_argument("--limit", type=positive_int, help="at most this many episodes")
    out = p.add_mutually_exclusive_group()
    out.add_argument("--save", metavar="FILE.rrd", help="write an .rrd file (the default: replay.rrd)")
    out.add_argument("--serve", action="store_true", help="serve the web viewer on localhost")
    out.add_argument("--spawn", action="store_true", help="open rerun's native viewer")
    p.add_argument("--live", action="store_true",
                   help="follow a run being written: stream each episode (a game, a reasoning) as it ends, "
                        "until the run stops")
    p.add_argument("--port", type=int, default=9876, help="gRPC port for --serve / --spawn (default 9876)")
    p.add_argument("--web-port", type=int, default=9090, help="web viewer port for --serve (default 9090)")
    p.add_argument("--why-depth", type=positive_int, default=6, help="depth of the why-trees (default 6)")
    p.add_argument("--lanes", default="alive,atLoc,health,ammo,action",
                   help="state lanes to draw, comma-separated (default: alive,atLoc,health,ammo,action)")
    p.add_argument("--color-by", metavar="PRED",
                   help="a run without a board: the predicate whose bound colours the nodes (default: the one "
                        "with the most changes over nodes)")
    p.add_argument("--why", metavar="ATOM", action="append", default=[],
                   help="a run without a board: show this atom's why-tree at each step, e.g. "
                        "--why 'exposed(http-tools)' (repeatable)")
    p.add_argument("--open-at", choices=("start", "end"), default="start",
                   help="where the viewer's time cursor starts (default: the first step)")


def _train(p: argparse.ArgumentParser) -> None:
    from tracelab.train.config import LEARNERS, RETIRED_FLAGS, config_fields
    for f in config_fields():
        flag, name = "--" + f.flag, f.name
        shown = f.help if f.default is None or isinstance(f.default, bool) else f"{f.help} (default: {f.default})"
        if name == "torch_deterministic":  # CleanRL's spelling: --torch-deterministic [true|false]
            p.add_argument(flag, dest=name, type=boolean, nargs="?", const=True, metavar="BOOL",
                           help=f"{shown} (default: on)")
            p.add_argument("--no-" + f.flag, dest=name, action="store_false", help=argparse.SUPPRESS)
            continue
        if f.type in ("bool", bool):
            kw: dict[str, Any] = {"action": "store_true"}
        elif name == "kernel":
            kw = {"choices": ENGINE_KERNELS}
        elif name == "learner":
            kw = {"choices": LEARNERS}
        else:
            conv = {"int": integer, "float": float, "str": str}.get(str(f.type), str)
            kw = {"type": conv, "metavar": f.flag.upper().replace("-", "_")}
        p.add_argument(flag, dest=name, help=shown, **kw)
        if f.alias:  # the field's own name, as earlier versions and docs wrote it: accepted, not listed
            p.add_argument("--" + f.alias, dest=name, help=argparse.SUPPRESS, **kw)
    # the war game's scenario, as its spec's id and params (gridwar_scenarios.ScenarioTraining.given)
    p.add_argument("--scenario", help="a built-in war game scenario (base, advanced, nonmarkov) or a scenario .toml "
                                      "file, trained as its spec (default: base, without --env)")
    p.add_argument("--agents", type=positive_int, help="the scenario's agents per team (default: the scenario's)")
    p.add_argument("--non-markov", dest="non_markov", action="store_true",
                   help="the scenario's non-Markov setup: the previous observation appended to the current one "
                        "(its spec's stack_previous)")
    p.add_argument("--markov", dest="non_markov", action="store_false",
                   help="the Markov setup: the current observation only (default)")
    p.add_argument("--opponent-p", type=float, metavar="P",
                   help="the scenario's opponent's probability of a move towards red's base while training (its "
                        "spec's p_toward; default 0.7)")
    p.add_argument("--eval-p", type=float, metavar="P",
                   help="the same in the evaluations (default 0.3)")
    for flag in RETIRED_FLAGS:  # RuleSim's trainer's: train refuses each in one line, saying why
        p.add_argument(flag, dest=flag, nargs="?", const="", help=argparse.SUPPRESS)
    p.add_argument("--exp-name", default=None, type=run_name, metavar="NAME",
                   help="name the run runs/NAME-<scenario>-<time> (default NAME: train)")
    p.add_argument("--run", default=None, help="run directory (default runs/train-<scenario>-<time>)")
    p.add_argument("--resume", default=None, metavar="RUN",
                   help="continue RUN's last checkpoint in RUN itself (its config; --total-timesteps may "
                        "raise the budget); with --run NEW, into a new run NEW instead")
    p.add_argument("--max-memory", type=byte_size, default=None, metavar="SIZE",
                   help="refuse a run whose networks, replay buffers and worlds are estimated to need more "
                        "(e.g. 12G; default: half of this machine's memory)")
    p.add_argument("--tensorboard", default=None, metavar="DIR",
                   help="also write the metrics as TensorBoard event files into DIR/<run name>/ while training "
                        "(needs the tensorboard package: pip install 'tracelab[tensorboard]')")
    p.add_argument("--env", default=None, metavar="SPEC_OR_ID",
                   help="train on this gymnasium env instead of the war game: a registered id "
                        "(tracelab/FrozenLake-v1, tracelab/Taxi-v4, ...) or a spec file (docs/worlds.md); a "
                        "Discrete observation is one-hot encoded for the network (docs/training.md)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of --env (repeatable), its value read as TOML: is_slippery=false")
    add_max_groundings(p)


def _eval(p: argparse.ArgumentParser) -> None:
    p.add_argument("policy", help="a policy directory (policy.json + policy.pt), e.g. RUN/policy")
    p.add_argument("--games", type=positive_int, default=500, help="games to play (default 500)")
    p.add_argument("--scenario", default=None,
                   help="play on this scenario (built-in name or .toml; default: the policy's own)")
    p.add_argument("--backend", choices=("rules", "reference"), default="rules",
                   help="rules (the default, and the only one left: every policy plays its world's spec)")
    p.add_argument("--opponent-p", type=float, default=None,
                   help="the war game's opponent's probability of a move towards red's base (default 0.3, the "
                        "method's evaluation, for a policy of RuleSim's trainer; a policy of train --env: "
                        "the p it was trained with)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the games (default 0)")
    p.add_argument("--num-envs", dest="envs", type=positive_int, default=64,
                   help="worlds stepped together (default 64, as train's --eval-envs)")
    p.add_argument("--envs", dest="envs", type=positive_int, help=argparse.SUPPRESS)  # the earlier name
    p.add_argument("--run", default=None, help="trace every game into this new run directory")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument("--env", default=None, metavar="SPEC_OR_ID",
                   help="play a policy trained with train --env on that env (the same id or spec file and "
                        "--env-arg values it was trained with)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of --env (repeatable), as train --env-arg")
    add_max_groundings(p)


def _runs(p: argparse.ArgumentParser) -> None:
    p.add_argument("dirs", nargs="*", metavar="DIR",
                   help="directories holding runs, or runs themselves (default: runs/ and sample_runs/)")
    add_format_options(p)


def _tui(p: argparse.ArgumentParser) -> None:
    p.add_argument("paths", nargs="*", metavar="RUN|DIR",
                   help="a run to open (several runs: the first, with the others' curves overlaid in its Training "
                        "view), or directories of runs (default: runs/ and sample_runs/)")
    p.add_argument("--screenshots", metavar="DIR",
                   help="write the README's screenshots (PNG) to DIR and exit: tui-trace-why.png from the "
                        "first RUN (default sample_runs/advanced), tui-training.png from the second, a "
                        "training run (default sample_runs/base-train), tui-reasoning.png from the third, a "
                        "run without a board (default sample_runs/supply-chain) (needs rsvg-convert)")


def _experiment(p: argparse.ArgumentParser) -> None:
    p.add_argument("name", choices=EXPERIMENT_NAMES, help="the experiment")
    p.add_argument("--seeds", type=positive_int, default=None,
                   help="seeds per setting (default: the experiment's, >= 3)")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="training steps per run (default: the experiment's)")
    p.add_argument("--eval-games", type=positive_int, default=None,
                   help="games per evaluation and per final evaluation (default 500)")
    p.add_argument("--quick", action="store_true",
                   help="a smoke run: few steps, one seed, a small evaluation, small plots (under 2 minutes)")
    p.add_argument("--jobs", type=positive_int, default=1,
                   help="trainings run at a time, each in its own process (default 1)")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="run each training as a Ray task: on a local Ray started for the command, limited to this "
                        "machine's cores, or on the Ray cluster at ADDRESS (host:port, auto, ray://...); --out "
                        "must then be a folder every node sees (docs/scaling.md; pip install 'tracelab[ray]')")
    p.add_argument("--kernel", choices=ENGINE_KERNELS, default="auto",
                   help="the rule engine's kernel of the trainings (train --kernel; default auto)")
    p.add_argument("--out", default=None, help="directory of the runs (default runs/experiments/NAME)")
    p.add_argument("--report-dir", default=None,
                   help="where NAME.md and NAME/*.png go (default docs/experiments; with --quick: --out)")
    p.add_argument("--report-only", action="store_true",
                   help="write the report and plots again from the finished experiment in --out (no training)")


def _sweep(p: argparse.ArgumentParser) -> None:
    from tracelab.train.sweep_spec import DEFAULT_METRIC, MODES, SCHEDULERS
    p.add_argument("spec", nargs="?", default=None, metavar="SWEEP.toml",
                   help="a sweep file ([set], [grid], [random], samples, scheduler, metric, mode); the flags "
                        "below add to it")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="a training setting of every trial, e.g. steps=20000 (repeatable; any train flag's field; "
                        "env=SPEC_OR_ID trains every trial on that env, as train --env)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of the --set env=... (its spec's [params]; repeatable)")
    p.add_argument("--grid", action="append", default=[], metavar="FIELD=V1,V2,...",
                   help="try each value, e.g. lr=1e-4,3e-4 (repeatable; grids multiply)")
    p.add_argument("--random", action="append", default=[], metavar="FIELD=DIST:LOW,HIGH",
                   help="draw the field per trial: uniform:A,B, loguniform:A,B (floats), randint:A,B (integers, "
                        "both bounds included) or choice:V1,V2 (repeatable)")
    p.add_argument("--samples", type=positive_int, default=None,
                   help="trials drawn (default 1); with --grid, per grid point")
    p.add_argument("--scheduler", choices=SCHEDULERS, default=None,
                   help="fifo: every trial trains to the end (default); asha: trials behind the others at an "
                        "evaluation stop there (needs eval_every below steps)")
    p.add_argument("--metric", default=None, help=f"the metric Tune compares (default {DEFAULT_METRIC}, the "
                                                  f"evaluations' win rate of the method)")
    p.add_argument("--mode", choices=MODES, default=None, help="max (default) or min of --metric")
    p.add_argument("--out", default=None, help="directory of the trials' runs (default runs/sweeps/sweep-<time>); "
                                               "on a cluster, a folder every node sees")
    p.add_argument("--ray", default="local", metavar="ADDRESS",
                   help="the Ray cluster (host:port, auto, ray://...; default: a local Ray started for the "
                        "command, limited to this machine's cores)")
    p.add_argument("--max-memory", type=byte_size, default=None, metavar="SIZE",
                   help="refuse a sweep whose largest trial's networks, replay buffers and worlds are estimated "
                        "to need more, as train does (e.g. 12G; default: half of this machine's memory)")


def _compile(p: argparse.ArgumentParser) -> None:
    p.add_argument("program", nargs="+", help="rule files (merged into one program, as `reason` merges them)")
    add_max_groundings(p)


def _compare(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", metavar="RUN",
                   help="training runs: directories, .duckdb files or names under runs/")
    add_format_options(p)


def _export(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("--tensorboard", required=True, metavar="DIR",
                   help="write TensorBoard event files into DIR/<run name>/ (needs the tensorboard package: "
                        "pip install 'tracelab[tensorboard]')")


def _rewards(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="TERM=VALUE",
                   help="re-score with TERM's value per occurrence VALUE (repeatable): a spec's [reward.table] key "
                        "(quote it: --set 'home(me)=5') or its scaled atom (VALUE: the scale); a RuleSim run's win, "
                        "loss, hit, got_shot, step, unsafe, invalid")
    p.add_argument("--episode", "-e", type=non_negative_int, help="this episode only (default: every episode)")
    p.add_argument("--json", action="store_true", help="the table as JSON")


def _whatif(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run directory, .duckdb file, or run name under runs/ (a spec world's: play --env, "
                               "train --env's traced evaluations)")
    p.add_argument("--episode", "-e", type=non_negative_int, required=True, help="the episode to branch")
    p.add_argument("--at", type=positive_int, required=True, help="the step (from 1) whose action is replaced")
    p.add_argument("--action", required=True, metavar="NAME", help="the action taken at --at, by its name in the "
                                                                   "spec's [actions]")
    p.add_argument("--agent", default=None, help="the agent whose action is replaced (default: the run's only one)")
    p.add_argument("--policy", default=None, metavar="RUN/policy",
                   help="play on with this policy's greedy actions (trained by train --env on the run's env); "
                        "default: the recorded actions, until they run out")
    p.add_argument("--steps", type=positive_int, default=None, help="play at most this many steps after --at")
    p.add_argument("--run", dest="out", default=None, metavar="OUT",
                   help="a new (or empty) run directory for the branch (default runs/whatif-<run>-e<E>-t<T>-<time>)")
    p.add_argument("--json", action="store_true", help="the comparison as JSON")


COMMANDS = (
    Command("play", _play,
            "play traced games of a world (the war game's --scenario, or a spec's --env; red: a random or a trained "
            "policy) into a trace-store run"),
    Command("reason", _reason,
            "run a rule program and print its trace and final interpretation"),
    Command("convert-pyreason", _convert_pyreason,
            "write PyReason rules/facts/graph as a tracelab program"),
    Command("run-pyreason", _run_pyreason,
            "run a PyReason script unchanged on tracelab"),
    Command("trace", _trace,
            "the trace table of an episode: every bound change and its rule"),
    Command("why", _why,
            "why an atom had its bound at a time: the rules, facts and actions behind it"),
    Command("why-not", _why_not,
            "the first body clause of a rule that failed for a grounding at a time"),
    Command("sql", _sql,
            "read-only SQL on a run, or on several (a `run` column): views changes, firings, episodes, steps, "
            "metrics, rules, facts, atoms, groundings, run",
            usage="tracelab sql [options] RUN [RUN ...] QUERY\n"
                  "       tracelab sql [options] RUN [RUN ...] --query NAME [-p NAME=VALUE ...]\n"
                  "       tracelab sql --list"),
    Command("diff", _diff,
            "what two episodes were given, where they ended and where they first diverge, of one run (RUN A B) or "
            "of two runs (RUN_A[:EP] RUN_B[:EP])",
            description="What two episodes were given (rules and facts of one side only), where they ended (atoms "
                        "with other bounds at the end) and where they first diverge: `diff RUN A B` compares "
                        "episodes A and B of one run, `diff RUN_A:EP RUN_B:EP` an episode of each of two runs, "
                        "`diff RUN_A RUN_B` two runs of one episode each (atoms, rules, facts and causes are "
                        "compared by their text, so the runs' ids may differ)."),
    Command("seal", _seal,
            "compact a finished run into <run>/run.duckdb"),
    Command("bench", _bench,
            "benchmarks: engine compile/start-up/steps/memory, simulators and envs, trace store"),
    Command("check", _check,
            "verify a run's files; --repair quarantines damaged parts"),
    Command("show", _show,
            "a run's metadata, program, scenario and counts"),
    Command("replay", _replay,
            "replay traced games (or a reasoning over a graph) in rerun's viewer, with the fired rules annotated"),
    Command("train", _train,
            "train red with DQN, logging metrics, episodes and traced evaluation games into a run",
            argument_default=argparse.SUPPRESS),
    Command("eval", _eval,
            "evaluate a saved policy on its world's spec: wins, losses, draws, truncations, the method's win rate"),
    Command("runs", _runs,
            "list runs: status, command, scenario, episodes, rows, size, start"),
    Command("tui", _tui,
            "terminal UI: browse runs, traces, why-trees, rules, SQL, training curves"),
    Command("experiment", _experiment,
            "run one of the method's experiments: train (one run per seed), evaluate, write a report with plots "
            "under docs/experiments/"),
    Command("sweep", _sweep,
            "search training settings with Ray Tune (grid, random, ASHA early stopping): one run per trial under "
            "--out, the best trial named at the end"),
    Command("compile", _compile,
            "compile a rule program to its own kernel and cache it on disk"),
    Command("compare", _compare,
            "training runs side by side: final metrics and the config keys that differ",
            description="Training runs (from `tracelab train`) side by side, one column per run: their status and "
                        "last step, the config keys whose values differ, and each metric's value at the run's end "
                        "(win rates also at their best, 'VALUE @STEP'). For a run's episodes see `tracelab diff`."),
    Command("export", _export,
            "a training run's metrics for other tools: TensorBoard event files",
            description="Convert a training run's metrics (every row of its `metrics`, at its step and wall time) "
                        "into TensorBoard event files in DIR/<run name>/; `tensorboard --logdir DIR` then shows it "
                        "beside other runs exported or trained (train --tensorboard) into DIR."),
    Command("rewards", _rewards,
            "each episode's return by reward term, or re-scored with other term values (--set) from the record, "
            "without re-simulating"),
    Command("whatif", _whatif,
            "replay a recorded game of a spec world to a step, take another action there, play on, and show the "
            "branch beside the original",
            description="Rebuild the world of episode E at step T from the run (its spec and rule texts, its "
                        "seeds, its recorded actions), take NAME at step T instead, play on with --policy's greedy "
                        "actions or the recorded ones, record the branch as the one episode of a new run (--run) "
                        "that names its origin, and print both games' return, outcome, return by reward term and "
                        "first divergence."),
)
BY_NAME = {c.name: c for c in COMMANDS}
