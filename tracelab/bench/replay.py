"""`tracelab bench replay`: how fast `tracelab replay` turns traced games into a rerun .rrd file.

Two runs are written first (not timed), sealed, then converted `repeats` times each:
- one 5v5 game of war.toml's base game (war.toml, agents_per_team 5, up to 500 steps; the opponent's
  p_toward 0 and red mostly idle, so that the game runs long), goal <= 0.5 s;
- 100 games of 1v1 (the advanced game, random red against the rules' opponent), goal <= 5 s.
A conversion is everything `tracelab replay RUN --save FILE` does after start-up: open the run, read
what its episodes share, rebuild and log every episode, write the file (merging the recordings of
several episodes with `rerun rrd merge`). Medians, with a breakdown of the 5v5 game by layer.

The games are played through war.toml (rules/gridworld/) as `tracelab play --env` plays it,
with its run metadata (the spec, its params, its `[board]`): what is measured is the path every world's
replay takes."""
from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.bench.common import Summary, format_table, machine_info, summarize
from tracelab.bench.engine import machine_line
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar import WAR_SPEC
from tracelab.envs.declared.play import load_declared, make_declared_env, play_episodes, random_policy
from tracelab.store import TraceWriter, seal_run
from tracelab.store.reader import open_run
from tracelab.viewers.replay import agent_plots, board_layer, graph_rules, lanes, plots
from tracelab.viewers.replay.graph_run import read_episode
from tracelab.viewers.replay.outputs import SaveOutput
from tracelab.viewers.replay.recording import ReplayOptions, RunContext, new_recording
from tracelab.viewers.replay.replay import context_of, replay_run
from tracelab.viewers.replay.select import EpisodeFilter

GOAL_5V5_S = 0.5
GOAL_100_GAMES_S = 5.0


def write_games(run_dir: Path, params: dict[str, Any], games: int, seed: int = 0, idle: float = 0.0) -> None:
    """`games` traced games of war.toml with `params`, written to a new run as `tracelab play --env` writes
    them: red random, or idle (the action `nothing`) with probability `idle`."""
    source = EnvSource(str(WAR_SPEC), params)
    spec = load_declared(source)
    config = {"env": source.name, "env_id": None, "spec_path": str(WAR_SPEC), "env_args": params,
              "episodes": games, "policy": "random"}
    meta = {"command": "tracelab bench replay", "config": config, "rule_files": list(spec.program.files),
            "seed": seed}
    env = make_declared_env(source, spec, trace_writer=TraceWriter.open(run_dir, meta))
    rng, noop = np.random.default_rng(seed), spec.action_names.index("nothing")
    random_red = random_policy(env, seed)

    def act(obs: Any, info: dict[str, Any]) -> Any:
        actions = random_red(obs, info)
        return np.where(rng.random(np.shape(actions)) < idle, noop, actions)
    play_episodes(env, games, seed, act)
    env.close()
    seal_run(run_dir)


def write_idle_game(run_dir: Path, agents: int = 5, steps: int = 500, seed: int = 0) -> None:
    """One traced game of `agents` a team that lasts up to `steps` steps: red does nothing 80% of the time,
    and the opponent never heads for red's base on purpose (p_toward 0)."""
    write_games(run_dir, {"agents_per_team": agents, "max_steps": steps, "p_toward": 0.0}, 1, seed, idle=0.8)


def write_1v1_games(run_dir: Path, games: int = 100, seed: int = 0) -> None:
    """`games` traced 1v1 games of the advanced game, random red."""
    write_games(run_dir, {"advanced": True}, games, seed)


def convert(run: Path, out: Path) -> int:
    """`tracelab replay RUN --save OUT` without the process start-up; returns the recordings written."""
    con = open_run(run)
    try:
        return replay_run(context_of(con, run.name), EpisodeFilter(), SaveOutput(out))
    finally:
        con.close()


def wall_and_cpu(fn: Callable[[], object], repeats: int) -> tuple[Summary, Summary]:
    """Wall-clock seconds and CPU seconds (this process and its children: `rerun rrd merge`) of
    `repeats` calls. On a shared machine the CPU time is the steadier figure: the wall clock also counts
    the time other processes held the cores."""
    walls, cpus = [], []
    for _ in range(max(1, repeats)):
        t0, c0 = time.perf_counter(), _cpu_seconds()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(_cpu_seconds() - c0)
    return summarize(walls), summarize(cpus)


def _cpu_seconds() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _model_of(ctx: RunContext) -> Callable[[], Any]:
    return lambda: ctx.model


def layer_times(run: Path, repeats: int) -> dict[str, float]:
    """Median seconds of each part of converting the run's first episode (recording kept in memory), in
    the order record_episode logs them."""
    con = open_run(run)
    ctx = context_of(con, run.name)
    ctx.check(ReplayOptions(), 0)                # the lanes the run can draw, as `replay_run` decides them
    episode = con.execute("SELECT min(episode) FROM episodes WHERE steps > 0").fetchall()[0][0]
    times: dict[str, list[float]] = {}
    for _ in range(repeats):
        rec = new_recording(run.name, episode)
        memory = rec.memory_recording()
        t0 = time.perf_counter()
        data = read_episode(con, None, episode, None, edges=False)
        rows = ctx.step_rows(episode)
        agent = agent_plots.read_series(con, episode)
        times.setdefault("read (rule log, changes, rewards)", []).append(time.perf_counter() - t0)
        agents = list(dict.fromkeys(a for _, a, *_ in rows))
        deaths: dict[int, list[str]] = {}

        def board(rec: Any, deaths: dict[int, list[str]]) -> None:
            deaths.update(board_layer.log_board(rec, con, ctx.board, episode).deaths())

        for name, fn, args in (("board", board, (rec, deaths)),
                               ("plots", plots.log_rewards, (rec, plots.agent_rewards(agents, rows), agents)),
                               ("agent plots", agent_plots.log_agent_series, (rec, agent)),
                               ("state lanes", lanes.log_lanes, (rec, con, episode, ctx.lanes, rows)),
                               ("rule log", graph_rules.log_rule_log, (rec, data)),
                               ("changes per step", graph_rules.log_changed, (rec, data)),
                               ("why documents", graph_rules.log_why,
                                (rec, con, data, (), 6, _model_of(ctx), graph_rules.no_edges, deaths,
                                 plots.step_notes(rows))),
                               ("flush", rec.flush, ())):
            t0 = time.perf_counter()
            fn(*args)
            times.setdefault(name, []).append(time.perf_counter() - t0)
        memory.drain_as_bytes()
    con.close()
    return {k: summarize(v).median for k, v in times.items()}


def run(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    """--quick: a 2v2 game of up to 100 steps and 10 games of 1v1 (a smoke run, not for figures)."""
    info = machine_info()
    agents, steps, games = (2, 100, 10) if quick else (5, 500, 100)
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-replay-") as tmp:
        tmp_path = Path(tmp)
        big, many = tmp_path / f"game{agents}v{agents}", tmp_path / f"games1v1x{games}"
        write_idle_game(big, agents, steps)
        write_1v1_games(many, games)
        convert(big, tmp_path / "warm.rrd")                       # warm-up: imports, first queries
        one, one_cpu = wall_and_cpu(lambda: convert(big, tmp_path / "big.rrd"), repeats)
        hundred, hundred_cpu = wall_and_cpu(lambda: convert(many, tmp_path / "many.rrd"), repeats)
        layers = layer_times(big, repeats)
        con = open_run(big)
        played = con.execute("SELECT steps FROM episodes WHERE steps > 0").fetchall()[0][0]
        rows = con.execute("SELECT count(*) FROM raw.changes").fetchall()[0][0]
        con.close()
        sizes = {"big_rrd_bytes": (tmp_path / "big.rrd").stat().st_size,
                 "many_rrd_bytes": (tmp_path / "many.rrd").stat().st_size}
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "agents": agents, "steps": played,
            "trace_rows": rows, "games": games, "one_game_s": one.to_dict(), "games_s": hundred.to_dict(),
            "one_game_cpu_s": one_cpu.to_dict(), "games_cpu_s": hundred_cpu.to_dict(),
            "layers_s": layers, **sizes, "goals": {"one_game_s": GOAL_5V5_S, "games_s": GOAL_100_GAMES_S}}


def report(r: dict[str, Any]) -> str:
    one, many = r["one_game_s"], r["games_s"]
    n = r["agents"]
    table = format_table(["replay conversion (run -> .rrd)", "wall s", "spread", "CPU s", "goal s"], [
        [f"one {n}v{n} game of {r['steps']} steps ({r['trace_rows']:,} trace rows)", one["median"],
         f"{100 * one['spread']:.0f}%", r["one_game_cpu_s"]["median"], GOAL_5V5_S if not r["quick"] else ""],
        [f"{r['games']} games of 1v1", many["median"], f"{100 * many['spread']:.0f}%",
         r["games_cpu_s"]["median"], GOAL_100_GAMES_S if not r["quick"] else ""],
    ])
    layers = format_table([f"the {n}v{n} game by layer", "median s"], [[k, v] for k, v in r["layers_s"].items()])
    return (machine_line(r["machine"], r["quick"], r["repeats"]) + "\n\n" + table + "\n\n" + layers +
            f"\n\n.rrd sizes: {r['big_rrd_bytes'] / 1e6:.1f} MB (one game), {r['many_rrd_bytes'] / 1e6:.1f} MB "
            f"({r['games']} games)")
