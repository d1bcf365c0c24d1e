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

OUTCOMES = {0: "win", 1: "loss", 2: "draw"}  # from red's side, by WINNER_RED / BLUE / DRAW


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("play", help="play traced games (red: a simple policy; blue: the scripted "
                                    "opponent) into a trace-store run")
    p.add_argument("--scenario", default="advanced",
                   help="a built-in scenario name (base, advanced, nonmarkov) or a scenario .toml file")
    p.add_argument("--episodes", type=int, default=5, help="episodes to play (default 5)")
    p.add_argument("--worlds", type=int, default=1, help="worlds stepped together (default 1)")
    p.add_argument("--policy", choices=("random", "scripted"), default="scripted",
                   help="red's policy (default: the scripted base policy)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--run", help="run directory (default runs/play-<scenario>-<time>)")
    p.add_argument("--no-trace", action="store_true", help="play without recording a run")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tracelab.game.scenario import (
        ScenarioError,
        builtin_scenario,
        builtin_scenario_names,
        load_scenario,
    )

    try:
        scenario = builtin_scenario(args.scenario) if args.scenario in builtin_scenario_names() \
            else load_scenario(args.scenario)
    except (ScenarioError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.episodes < 1 or args.worlds < 1:
        print("error: --episodes and --worlds must be at least 1", file=sys.stderr)
        return 2
    if args.no_trace:
        _summary(play(scenario, args, sink=None))
        return 0
    from tracelab.game.facts import GAME_RULES
    from tracelab.store import TraceWriter
    from tracelab.store.sink import StoreSink

    run_dir = Path(args.run or f"runs/play-{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    meta = {"command": " ".join(shlex.quote(a) for a in sys.argv), "scenario": scenario.name,
            "config": {"episodes": args.episodes, "worlds": args.worlds, "policy": args.policy,
                       "scenario": scenario.to_toml()},
            "rule_files": [str(GAME_RULES)], "seed": args.seed}
    stats = play(scenario, args, sink=StoreSink(TraceWriter.open(run_dir, meta)))
    _summary(stats)
    _what_to_open(run_dir)
    return 0


def play(scenario, args: argparse.Namespace, sink) -> dict:
    """Play exactly args.episodes episodes in args.worlds worlds of the vector env (rules backend). The
    env numbers episodes in the order they begin (its autoreset begins a new one in every world that
    ended); episodes numbered past the last one asked for are played but neither counted nor recorded
    (trace_episodes), so the run holds exactly the episodes asked for, none of them cut short."""
    from tracelab.envs.vector_env import GridWarVectorEnv

    n_worlds = min(args.worlds, args.episodes)
    env = GridWarVectorEnv(n_worlds, scenario, backend="rules", trace_sink=sink,
                           trace_episodes=args.episodes)
    rng = np.random.default_rng(args.seed)
    index_of = {a: i for i, a in enumerate(scenario.action_ids)}
    to_index = np.array([index_of.get(a, 0) for a in range(9)])  # spec action id -> action index
    n = scenario.agents_per_team
    env.reset(seed=args.seed)
    episode_of_world = np.arange(n_worlds)
    next_episode = n_worlds
    finished: dict[int, dict] = {}
    returns = np.zeros(n_worlds)
    steps = 0
    t0 = time.perf_counter()
    while len(finished) < args.episodes:
        if args.policy == "scripted":
            red = to_index[env.sim.scripted_actions("red")]
        else:
            red = rng.integers(0, scenario.n_actions, size=(n_worlds, n))
        _, reward, terminated, truncated, info = env.step(red[:, 0] if n == 1 else red)
        playing = episode_of_world < args.episodes
        steps += int(playing.sum())
        returns += reward
        done = np.flatnonzero(terminated | truncated)
        for w in done:
            if episode_of_world[w] < args.episodes:
                final = info["final_info"]
                finished[int(episode_of_world[w])] = {
                    "steps": int(final["t"][w]), "outcome": OUTCOMES.get(int(final["winner"][w]), "truncated"),
                    "return": float(returns[w])}
            returns[w] = 0.0
        episode_of_world[done] = next_episode + np.arange(len(done))  # as the env numbers them
        next_episode += len(done)
    elapsed = time.perf_counter() - t0
    env.close()
    return {"episodes": [finished[e] for e in sorted(finished)], "steps": steps, "seconds": elapsed,
            "scenario": scenario.name}


def _summary(stats: dict) -> None:
    eps = stats["episodes"]
    outcomes = {k: sum(e["outcome"] == k for e in eps) for k in ("win", "loss", "draw", "truncated")}
    mean_return = np.mean([e["return"] for e in eps]) if eps else 0.0
    print(f"played {len(eps)} episodes of {stats['scenario']} ({stats['steps']} steps, "
          f"{stats['steps'] / max(stats['seconds'], 1e-9):,.0f} steps/s)")
    print("red: " + ", ".join(f"{v} {k}" for k, v in outcomes.items()) + f"; mean return {mean_return:.1f}")


def _what_to_open(run_dir: Path) -> None:
    from tracelab.store import open_run

    con = open_run(run_dir)
    ep = 0
    row = con.execute(
        "SELECT atom, t FROM changes WHERE episode = ? AND label = 'atLoc' AND atom LIKE 'atLoc(red-agent-1,%' "
        "AND new_lower = 1 ORDER BY t DESC LIMIT 1", [ep]).fetchone()
    con.close()
    run = shlex.quote(str(run_dir))
    print(f"\nrun written to {run_dir}/  — what to open:")
    print(f"  tracelab trace {run} --episode {ep} --from 1 --to 4        # the trace table (t=0: the map)")
    if row:
        print(f"  tracelab why {run} {shlex.quote(row[0])} --episode {ep} --at {row[1]}   # why is it true?")
    print(f"  tracelab sql {run} \"SELECT rule, count(*) AS n FROM firings GROUP BY rule ORDER BY n DESC\"")
    print(f"  tracelab sql {run} --query episode_summary")
    print(f"  tracelab seal {run}                                          # one .duckdb file")
