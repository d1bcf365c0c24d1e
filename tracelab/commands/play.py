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
    from tracelab.scenario import ScenarioError, builtin_scenario, builtin_scenario_names, load_scenario

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
        stats = play(scenario, args, writer=None)
        _summary(stats)
        return 0
    from tracelab.game_facts import GAME_RULES
    from tracelab.store import TraceWriter

    run_dir = Path(args.run or f"runs/play-{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    meta = {"command": " ".join(shlex.quote(a) for a in sys.argv), "scenario": scenario.name,
            "config": {"episodes": args.episodes, "worlds": args.worlds, "policy": args.policy,
                       "scenario": scenario.to_toml()},
            "rule_files": [str(GAME_RULES)], "seed": args.seed}
    with TraceWriter.open(run_dir, meta) as writer:
        stats = play(scenario, args, writer)
    _summary(stats)
    _what_to_open(run_dir, stats)
    return 0


def play(scenario, args: argparse.Namespace, writer) -> dict:
    """Play args.episodes episodes; with a writer, record program, changes, steps and episodes."""
    from tracelab.refsim import WINNER_NONE
    from tracelab.rulesim import RuleSim

    n_worlds = min(args.worlds, args.episodes)
    sim = RuleSim(scenario, n_worlds, seed=args.seed, trace=writer is not None)
    rng = np.random.default_rng(args.seed)
    ids = np.asarray(scenario.action_ids)
    n = scenario.agents_per_team
    red_agents = [f"red-agent-{j + 1}" for j in range(n)]
    # the global episode id of each world's current episode, and per-episode bookkeeping
    episode_of = np.arange(n_worlds)
    started = n_worlds
    returns = np.zeros(n_worlds)
    finished: list[dict] = []
    if writer is not None:
        writer.write_engine_program(sim.engine)
        for w in range(n_worlds):
            writer.begin_episode(int(episode_of[w]), world=w, t_start=0, seed=args.seed)
    active = np.ones(n_worlds, bool)
    obs = sim.reset()
    t0 = time.perf_counter()
    steps = 0
    while active.any():
        blue = sim.scripted_actions("blue")
        red = sim.scripted_actions("red") if args.policy == "scripted" else rng.choice(ids, size=(n_worlds, n))
        result = sim.step(red, blue)
        steps += int(active.sum())
        returns[active] += result.reward[active, 0]
        if writer is not None:
            _record_step(writer, sim, result, red, obs, episode_of, active, red_agents)
        obs = result.obs
        done = active & (result.terminated | result.truncated)
        for w in np.flatnonzero(done):
            winner = int(result.winner[w])
            outcome = "truncated" if winner == WINNER_NONE else OUTCOMES[winner]
            finished.append({"episode": int(episode_of[w]), "steps": int(result.t[w]), "outcome": outcome,
                             "return": float(returns[w])})
            if writer is not None:
                writer.end_episode(int(episode_of[w]), steps=int(result.t[w]), outcome=outcome,
                                   reward=float(returns[w]),
                                   rewards={a: float(x) for a, x in zip(red_agents, result.agent_reward[w, 0])})
        if done.any():
            again = done & (started < args.episodes)
            active &= ~(done & ~again)
            for w in np.flatnonzero(again):
                episode_of[w] = started
                started += 1
                returns[w] = 0.0
            if again.any():
                obs = sim.reset(worlds=again)
                if writer is not None:
                    for w in np.flatnonzero(again):
                        writer.begin_episode(int(episode_of[w]), world=int(w), t_start=0, seed=args.seed)
    elapsed = time.perf_counter() - t0
    return {"episodes": finished, "steps": steps, "seconds": elapsed, "scenario": scenario.name}


def _record_step(writer, sim, result, red, obs, episode_of, active, red_agents) -> None:
    rows = sim.take_trace()
    episode = episode_of[rows["world"]]
    keep = active[rows["world"]] | (rows["t"] == 0)
    rows = {k: v[keep] for k, v in rows.items() if k != "world_episode"}
    rows["episode"] = episode[keep]
    writer.write_vocabulary(sim.engine.vocabulary(), sim.engine.groundings)
    writer.write_changes(None, rows)
    n = len(red_agents)
    for w in np.flatnonzero(active):
        writer.write_steps(int(episode_of[w]), {
            "step": np.full(n, result.t[w]), "t": np.full(n, result.t[w]), "agent": red_agents,
            "action": red[w], "reward": result.agent_reward[w, 0],
            "terminated": np.full(n, result.terminated[w]), "truncated": np.full(n, result.truncated[w]),
            "obs": np.repeat(obs[w, 0][None], n, axis=0)})


def _summary(stats: dict) -> None:
    eps = stats["episodes"]
    outcomes = {k: sum(e["outcome"] == k for e in eps) for k in ("win", "loss", "draw", "truncated")}
    mean_return = np.mean([e["return"] for e in eps]) if eps else 0.0
    print(f"played {len(eps)} episodes of {stats['scenario']} ({stats['steps']} steps, "
          f"{stats['steps'] / max(stats['seconds'], 1e-9):,.0f} steps/s)")
    print("red: " + ", ".join(f"{v} {k}" for k, v in outcomes.items()) + f"; mean return {mean_return:.1f}")


def _what_to_open(run_dir: Path, stats: dict) -> None:
    from tracelab.store import open_run

    con = open_run(run_dir)
    ep = stats["episodes"][0]["episode"]
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
