"""`tracelab play`: play games of the rule-driven simulator, traced into a run of the trace store.

Red is played by a simple policy (random, or the scripted base policy), blue by the scripted opponent.
Every interpretation change of every episode goes to the run, with per-step actions and rewards, and
the command ends by saying what to open.
"""
from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from tracelab.commands._args import ENGINE_KERNELS, add_max_groundings, non_negative_int, positive_int
from tracelab.commands._interrupt import CtrlCBetweenSteps
from tracelab.commands._notices import say_running_compiles
from tracelab.commands._progress import compiling_engine, progress
from tracelab.commands._recording import read_for_hints, recording_into
from tracelab.commands.play_env import run_env
from tracelab.errors import UserError, store_errors

DEFAULT_SCENARIO = "base"  # the one train defaults to (TrainConfig.scenario)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("play", help="play traced games (red: a simple policy; blue: the scripted "
                                    "opponent) into a trace-store run")
    p.add_argument("--scenario", default=None,
                   help="a built-in scenario name (base, advanced, nonmarkov) or a scenario .toml file "
                        "(default: base, as train and eval, or the scenario a --policy PATH was trained on)")
    p.add_argument("--episodes", type=positive_int, default=5, help="episodes to play (default 5)")
    p.add_argument("--num-envs", dest="worlds", type=positive_int, default=1,
                   help="worlds stepped together (default 1)")
    for alias in ("--worlds", "--envs"):  # earlier spellings: accepted, not listed
        p.add_argument(alias, dest="worlds", type=positive_int, help=argparse.SUPPRESS)
    p.add_argument("--env", default=None, metavar="SPEC_OR_ID",
                   help="play a world declared in rules instead of the grid game: a spec file or a registered id "
                        "such as tracelab/FrozenLake-v1 (docs/worlds.md; a random policy unless --policy)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of the --env (its spec's [params]), e.g. is_slippery=false (repeatable)")
    p.add_argument("--policy", default=None,
                   help="red's policy: random, scripted (the scripted base policy, default) or the path of "
                        "a trained policy (e.g. RUN/policy); with --env, random (default) or a policy that "
                        "train --env trained on that env")
    p.add_argument("--opponent-p", type=float, default=None,
                   help="the opponent's probability of a move towards red's base (default 0.7)")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seed of the episodes and of the random policy (default 0)")
    p.add_argument("--kernel", choices=ENGINE_KERNELS, default="auto",
                   help="the rule engine's kernel: auto (default: lanes from 64 worlds, else counting, stepped "
                        "with the game as one compiled call), counting, lanes, or compiled (built in the "
                        "background while the games start on the counting kernel, unless `tracelab compile` "
                        "built it ahead)")
    p.add_argument("--run", help="a new (or empty) run directory (default runs/play-<scenario>-<time>)")
    p.add_argument("--no-trace", action="store_true", help="play without recording a run")
    add_max_groundings(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
    from tracelab.game.scenario import (
        builtin_scenario,
        builtin_scenario_names,
        load_scenario,
    )

    if args.env is not None or args.env_arg:  # a declared world: its own module (play_env.py)
        return run_env(args)
    args.policy = args.policy or "scripted"
    args.trained = None
    builtin = args.policy in ("random", "scripted")
    if not builtin:
        # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
        from tracelab.train.policy import load_policy, policy_scenario, read_policy_spec
        with store_errors():  # a policy that does not load is the user's to fix
            scenario = policy_scenario(read_policy_spec(args.policy))
    if args.scenario is not None or builtin:
        name = args.scenario or DEFAULT_SCENARIO
        scenario = builtin_scenario(name) if name in builtin_scenario_names() else load_scenario(name)
    if not builtin:
        with store_errors():
            args.trained = load_policy(args.policy, scenario)
    if args.no_trace:
        _summary(play(scenario, args, sink=None))
        return 0
    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.game.facts import GAME_RULES
    from tracelab.game.scenario import BOARD
    from tracelab.store import TraceWriter
    from tracelab.store.sink import StoreSink

    run_dir = Path(args.run or f"runs/play-{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.store.layout import check_new_run_dir
    check_new_run_dir(run_dir)
    meta = {"command": " ".join(shlex.quote(a) for a in sys.argv), "scenario": scenario.name,
            "config": {"episodes": args.episodes, "worlds": args.worlds, "policy": args.policy, "kernel": args.kernel,
                       "opponent_p": args.opponent_p, "scenario": scenario.to_toml()},
            "rule_files": [str(GAME_RULES)], "seed": args.seed, "board": BOARD}
    try:
        with store_errors():  # another process took the directory since the check: a RuntimeError
            writer = TraceWriter.open(run_dir, meta)
    except OSError as e:
        raise UserError(f"cannot create the run directory {run_dir}: {e.strerror or e}") from e
    with recording_into(writer, run_dir):
        stats = play(scenario, args, sink=StoreSink(writer))
    _summary(stats)
    _what_to_open(run_dir)
    return 0


def play(scenario, args: argparse.Namespace, sink) -> dict:
    """Play exactly args.episodes episodes in args.worlds worlds (tracelab.playing.Games), showing the
    compile (first run) or the build while it happens and a progress bar over the episodes (on a
    terminal); the steps/s leave out the first step, which includes any compiling."""
    # deferred: loads gymnasium, numba; every command is imported to build the CLI's parser
    from tracelab.engine.core import LANES_MIN_WORLDS
    from tracelab.playing import Games

    n = scenario.agents_per_team
    agents = f"{n} agent{'s' if n != 1 else ''} a team"
    kernel = getattr(args, "kernel", "auto")
    n_worlds = min(args.worlds, args.episodes)
    lanes = kernel == "lanes" or (kernel == "auto" and n_worlds >= LANES_MIN_WORLDS)
    with CtrlCBetweenSteps() as ctrl_c:
        with compiling_engine(simulator=True, lanes=lanes,
                              busy=f"building the game's rules ({agents})…") as first:
            games = Games(scenario, args.episodes, worlds=args.worlds, policy=args.policy,
                          trained=getattr(args, "trained", None), seed=args.seed, sink=sink, kernel=kernel,
                          opponent_p=getattr(args, "opponent_p", None))
            first_steps, ended = games.step()
        steps = 0
        t0 = time.perf_counter()
        with progress(f"playing {scenario.name}", total=args.episodes, unit="episodes") as bar:
            bar.advance(ended)
            while not games.done:
                ctrl_c.check()
                played, ended = games.step()
                steps += played
                if ended:
                    bar.advance(ended)
                    elapsed = time.perf_counter() - t0
                    bar.set_fields(wins=games.wins,
                                   **{"steps/s": steps / max(elapsed, 1e-9)})
    elapsed = time.perf_counter() - t0
    games.close()
    say_running_compiles()
    return {"episodes": [games.finished[e] for e in sorted(games.finished)], "steps": steps + first_steps,
            "timed_steps": steps, "seconds": elapsed, "scenario": scenario.name,
            "first_step_s": first.seconds, "compiled": first.compiled}


def _summary(stats: dict) -> None:
    eps = stats["episodes"]
    outcomes = {k: sum(e["outcome"] == k for e in eps) for k in ("win", "loss", "draw", "truncated")}
    mean_return = np.mean([e["return"] for e in eps]) if eps else 0.0
    rate = (f"{stats['timed_steps'] / stats['seconds']:,.0f} steps/s" if stats["timed_steps"]
            else "too short to time")
    first = (f"; compiling the engine and the first step took {stats['first_step_s']:.0f} s"
             if stats["compiled"] else "")
    print(f"played {len(eps)} episodes of {stats['scenario']} ({stats['steps']} steps, {rate} after the "
          f"first step{first})")
    print("red: " + ", ".join(f"{v} {k}" for k, v in outcomes.items()) + f"; mean return {mean_return:.1f}")


def _what_to_open(run_dir: Path) -> None:
    ep = 0
    row = read_for_hints(run_dir, lambda con: con.execute(
        "SELECT a.text, c.t FROM raw.changes c JOIN (SELECT atom, text FROM atoms WHERE label = 'atLoc' AND "
        "text LIKE 'atLoc(red-agent-1,%') a ON a.atom = c.atom WHERE c.episode = ? AND c.new_lower = 1 "
        "ORDER BY c.t DESC LIMIT 1", [ep]).fetchone())
    run = shlex.quote(str(run_dir))
    print(f"\nrun written to {run_dir}/  — what to open:")
    print(f"  tracelab trace {run} --episode {ep} --from 1 --to 4        # the trace table (the map, t=0, hidden)")
    if row:
        print(f"  tracelab why {run} {shlex.quote(row[0])} --episode {ep} --at {row[1]}   # why is it true?")
    print(f"  tracelab sql {run} \"SELECT rule, count(*) AS n FROM firings GROUP BY rule ORDER BY n DESC\"")
    print(f"  tracelab sql {run} --query episode_summary")
    print(f"  tracelab tui {run}                                           # browse it in the terminal")
    print(f"  tracelab replay {run} --episode {ep} --save replay.rrd            # a rerun recording of a game")
    print(f"  tracelab seal {run}                                          # one .duckdb file")
