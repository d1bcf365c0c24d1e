"""`tracelab play`: play games of the rule-driven simulator, traced into a run of the trace store.

Red is played by a simple policy (random, or the scripted base policy) or a trained one (`--policy PATH`,
a policy directory written by `tracelab train`), blue by the scripted opponent.
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
    p.add_argument("--scenario", default=None,
                   help="a built-in scenario name (base, advanced, nonmarkov) or a scenario .toml file "
                        "(default: advanced, or the scenario a --policy PATH was trained on)")
    p.add_argument("--episodes", type=int, default=5, help="episodes to play (default 5)")
    p.add_argument("--worlds", type=int, default=1, help="worlds stepped together (default 1)")
    p.add_argument("--policy", default="scripted",
                   help="red's policy: random, scripted (the scripted base policy, default) or the path of "
                        "a trained policy (e.g. RUN/policy)")
    p.add_argument("--opponent-p", type=float, default=None,
                   help="the opponent's probability of a move towards red's base (default 0.7)")
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

    args.trained = None
    try:
        if args.policy not in ("random", "scripted"):
            from tracelab.train.policy import load_policy, policy_scenario, read_policy_spec
            spec = read_policy_spec(args.policy)
            scenario = policy_scenario(spec)
        if args.scenario is not None or args.policy in ("random", "scripted"):
            name = args.scenario or "advanced"
            scenario = builtin_scenario(name) if name in builtin_scenario_names() else load_scenario(name)
        if args.policy not in ("random", "scripted"):
            args.trained = load_policy(args.policy, scenario)
    except (ScenarioError, OSError, ValueError, KeyError) as e:
        print(f"tracelab: error: {e}", file=sys.stderr)
        return 2
    if args.episodes < 1 or args.worlds < 1:
        print("tracelab: error: --episodes and --worlds must be at least 1", file=sys.stderr)
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
                       "opponent_p": args.opponent_p,
                       "scenario": scenario.to_toml()},
            "rule_files": [str(GAME_RULES)], "seed": args.seed}
    stats = play(scenario, args, sink=StoreSink(TraceWriter.open(run_dir, meta)))
    _summary(stats)
    _what_to_open(run_dir)
    return 0


def play(scenario, args: argparse.Namespace, sink) -> dict:
    """Play until args.episodes episodes ended, in args.worlds worlds of the vector env (rules backend);
    episodes still running then are closed as aborted."""
    from tracelab.envs.vector_env import GridWarVectorEnv

    from tracelab.game.opponent import P_TOWARD
    from tracelab.train.policy import may_act

    n_worlds = min(args.worlds, args.episodes)
    trained = args.trained
    env = GridWarVectorEnv(n_worlds, scenario, backend="rules", trace_sink=sink,
                           stack_previous=trained is not None and trained.stack_previous,
                           opponent_p=P_TOWARD if args.opponent_p is None else args.opponent_p)
    rng = np.random.default_rng(args.seed)
    index_of = {a: i for i, a in enumerate(scenario.action_ids)}
    to_index = np.array([index_of.get(a, 0) for a in range(9)])  # spec action id -> action index
    n = scenario.agents_per_team
    obs, info = env.reset(seed=args.seed)
    finished: list[dict] = []
    returns = np.zeros(n_worlds)
    steps = 0
    t0 = time.perf_counter()
    while len(finished) < args.episodes:
        if trained is not None:
            masks = info["action_mask"].reshape(n_worlds, n, -1) if trained.mask else None
            red = trained.act(obs, may_act(scenario, env.sim.state), masks)
        elif args.policy == "scripted":
            red = to_index[env.sim.scripted_actions("red")]
        else:
            red = rng.integers(0, scenario.n_actions, size=(n_worlds, n))
        obs, reward, terminated, truncated, info = env.step(red[:, 0] if n == 1 else red)
        steps += n_worlds
        returns += reward
        for w in np.flatnonzero(terminated | truncated):
            final = info["final_info"]
            finished.append({"steps": int(final["t"][w]),
                             "outcome": OUTCOMES.get(int(final["winner"][w]), "truncated"),
                             "return": float(returns[w])})
            returns[w] = 0.0
    elapsed = time.perf_counter() - t0
    env.close()
    return {"episodes": finished[:args.episodes], "steps": steps, "seconds": elapsed,
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
