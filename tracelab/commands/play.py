"""`tracelab play`: games of a world declared by a spec, traced into a run of the trace store.

The world is any declared world, `--env SPEC_OR_ID` (docs/worlds.md), or the war game's `--scenario NAME`
(a built-in scenario or a scenario .toml file, played through its spec in rules/gridworld/:
tracelab.envs.declared.gridwar_scenarios). Red (the learners) is played by a random policy or a trained one
(`--policy RUN/policy`); the war game's blue by its scripted opponent, written as rules. Every change of
every episode goes to the run with its cause, the actions, rewards by term and the policy's decisions, and
the command ends by saying what to open (tracelab/envs/declared/recording.py).
"""
from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.commands._cold_start import ColdStart, start_if_cold
from tracelab.commands._interrupt import CtrlCBetweenSteps
from tracelab.commands._notices import say_running_compiles
from tracelab.commands._progress import compiling_engine, progress
from tracelab.commands._recording import read_for_hints, recording_into
from tracelab.commands._worlds import env_source_of
from tracelab.engine.errors import is_interrupt
from tracelab.envs.declared.gridwar_scenarios import (
    load_trained,
    read_rulesim_spec,
    refuse_scenario_flags,
    scenario_world,
    with_opponent_p,
)
from tracelab.envs.declared.play import load_declared, make_declared_env, play_episodes, random_policy
from tracelab.errors import UserError, store_errors
from tracelab.store import TraceWriter
from tracelab.store.layout import check_new_run_dir
from tracelab.train.env_policy import ENV_FORMAT, EVAL_STEP_CAP, greedy_actor, policy_format, recorded_env


def run(args: argparse.Namespace) -> int:
    source, scenario, trained = _world(args)
    spec = load_declared(source)
    cold = start_if_cold(spec, args.kernel, args.argv)  # empty caches: play at once, compile in the background
    try:
        return _run(args, source, scenario, trained, spec, cold)
    finally:
        if cold is not None:  # the compiled kernels again for whatever this process runs next
            cold.kernels.restore()


def _run(args: argparse.Namespace, source: Any, scenario: Any, trained: Any, spec: Any,
         cold: ColdStart | None) -> int:
    if args.no_trace:
        _summary(_name(source, scenario), spec,
                 _play(source, spec, trained, args, None, _name(source, scenario), cold))
        _say_compiles(cold)
        return 0

    run_dir = Path(args.run or f"runs/play-{_name(source, scenario)}-{time.strftime('%Y%m%d-%H%M%S')}")
    check_new_run_dir(run_dir)
    try:
        with store_errors():  # another process took the directory since the check: a RuntimeError
            writer = TraceWriter.open(run_dir, run_meta(source, spec, args, scenario))
    except OSError as e:
        raise UserError(f"cannot create the run directory {run_dir}: {e.strerror or e}") from e
    with recording_into(writer, run_dir):
        stats = _play(source, spec, trained, args, writer, _name(source, scenario), cold)
    _summary(_name(source, scenario), spec, stats)
    _what_to_open(run_dir, spec)
    _say_compiles(cold)
    return 0


def _say_compiles(cold: ColdStart | None) -> None:
    """At the end: what the background compiles (this play's, the compiled backend's) came to."""
    if cold is not None:
        print(cold.final_line(), file=sys.stderr, flush=True)
    say_running_compiles()


def _world(args: argparse.Namespace) -> tuple[Any, Any, Any]:
    """(the EnvSource played, the war game's Scenario or None, the loaded trained policy or None)."""
    if args.policy == "scripted":
        raise UserError("--policy scripted: red's scripted policy was the grid simulator's; play takes random "
                        "(the default) or a trained policy (RUN/policy)")
    path = args.policy if args.policy not in (None, "random") else None
    with store_errors():  # a policy that does not load is the user's to fix
        # a policy of RuleSim's trainer names its scenario (and whether it saw the previous step)
        rulesim = None if path is None or policy_format(path) == ENV_FORMAT else read_rulesim_spec(path)
    if args.env is not None:
        refuse_scenario_flags(args, "--env plays the world its spec declares (war.toml takes --env-arg "
                                    "p_toward=...)")
        source, scenario = env_source_of(args), None
    elif args.env_arg:
        raise UserError("--env-arg goes with --env")
    elif path is not None and rulesim is None and args.scenario is None:
        return _recorded(args, path)
    else:
        with store_errors():  # a scenario that does not load
            scenario, source = scenario_world(args, rulesim)
    if path is None:
        return source, scenario, None
    with store_errors():  # a policy that does not load, or was trained on another world
        return source, scenario, load_trained(path, source)


def _recorded(args: argparse.Namespace, path: str) -> tuple[Any, None, Any]:
    """A policy of train without --env: the env it was trained on where that is one of tracelab's ids (its
    scripted opponent at --opponent-p); a spec file the user names with --env."""
    with store_errors():  # a policy that does not load
        source = recorded_env(path)
        if source is None:
            raise UserError(f"{path} was trained with train --env on a spec file: name that env with --env "
                            "SPEC_OR_ID (and its --env-arg values); its policy.json says which under \"env\"")
        refuse_scenario_flags(args, f"{path} plays the env it was trained on ({source.describe()})", ("agents",))
        policy = load_trained(path, source)
    return with_opponent_p(source, args.opponent_p), None, policy


def _name(source: Any, scenario: Any) -> str:
    return source.short_name if scenario is None else scenario.name


def run_meta(source: Any, spec: Any, args: argparse.Namespace, scenario: Any = None) -> dict[str, Any]:
    """The run's metadata: the command, the world (id or spec file, its arguments, the spec and the rule files
    by path, size and hash: their texts go in the run's `sources` table), what sets each external fact
    and the board's rows (the recorder adds those: recording.declared_run_config); the war game's scenario by
    name and as its TOML."""
    spec_path, params = source.declared()
    config = {"env": source.name, "env_id": source.env_id, "spec_path": spec_path,
              "env_args": params, "episodes": args.episodes, "policy": args.policy or "random",
              "kernel": args.kernel}
    meta = {"command": " ".join(shlex.quote(a) for a in ["tracelab", *args.argv]), "config": config,
            "rule_files": list(spec.program.files), "seed": args.seed}
    if scenario is not None:
        config["scenario"] = scenario.to_toml()
        meta["scenario"] = scenario.name
    return meta


def _play(source: Any, spec: Any, trained: Any, args: argparse.Namespace, writer: Any,
          name: str, cold: ColdStart | None = None) -> dict[str, Any]:
    """args.episodes episodes of the world, showing the compile (first run) or the build while it happens
    and a progress bar over the episodes (on a terminal); `cold`: the kernels run as Python until its
    background compile is done (then from the next episode on, compiled)."""
    with compiling_engine(busy=f"building {name}'s rules…", local_trace=writer is not None,
                          phase=None):  # the declared world says what compiles (its library notice)
        env = make_declared_env(source, spec, kernel=args.kernel,
                                **({} if writer is None else {"trace_writer": writer}))
    if trained is None:
        policy, cap = random_policy(env, args.seed), None
    else:  # greedy: it may walk in circles where the env sets no step limit (CliffWalking)
        policy, cap = greedy_actor(trained, env), EVAL_STEP_CAP
    try:
        with CtrlCBetweenSteps() as ctrl_c, \
                progress(f"playing {name}", total=args.episodes, unit="episodes") as bar:
            def act(obs: Any, info: dict[str, Any]) -> Any:
                ctrl_c.check()  # a Ctrl-C stops the game between two steps (see CtrlCBetweenSteps)
                return policy(obs, info)

            def episode_done(_: dict[str, Any]) -> None:
                bar.advance(1)
                if cold is not None:
                    cold.between_episodes(bar.completed)

            stats = play_episodes(env, args.episodes, args.seed, act, on_episode=episode_done, step_cap=cap)
    except BaseException as e:  # the run records how it ended, with what was played until then
        env.unwrapped.close(status="interrupted" if is_interrupt(e) else "failed")
        raise
    env.close()  # a traced env closes its writer: the last rows and episode ends are written
    return stats


def _summary(name: str, spec: Any, stats: dict[str, Any]) -> None:
    eps = stats["episodes"]
    returns = np.array([e["return"] for e in eps])
    rate = f"{stats['steps'] / stats['seconds']:,.0f} steps/s" if stats["seconds"] > 0 else "too short to time"
    print(f"played {len(eps)} episodes of {name} ({stats['steps']} steps, {rate})")
    outcomes = [e["outcome"] for e in eps]
    truncated = f"{outcomes.count('truncated')} truncated; mean return {returns.mean():.2f}"
    if spec.win:  # the spec's `[end] win/loss` says what counts
        print(f"{outcomes.count('win')} won, {outcomes.count('loss')} lost, {truncated}")
    else:
        print(f"{int((returns > 0).sum())} with a positive return, {truncated}")


def _what_to_open(run_dir: Path, spec: Any) -> None:
    names = [str(a) for a, _ in spec.reward_table[0]]
    best = read_for_hints(run_dir, lambda con: con.execute(
        "SELECT episode, t_end FROM raw.episode_end ORDER BY reward DESC, steps, episode LIMIT 1").fetchone())
    row = None
    if best is not None and names:
        row = read_for_hints(run_dir, lambda con: con.execute(
            "SELECT a.text, c.t FROM raw.changes c JOIN (SELECT atom, text FROM atoms WHERE text IN "
            "(SELECT unnest(?))) a ON a.atom = c.atom WHERE c.episode = ? AND c.new_lower = 1 "
            "ORDER BY c.t DESC LIMIT 1", [names, best[0]]).fetchone())
    run = shlex.quote(str(run_dir))
    ep, last = best if best else (0, 1)
    print(f"\nrun written to {run_dir}/  — what to open:")
    print(f"  tracelab sql {run} \"SELECT episode, steps, reward, outcome FROM episodes "
          f"ORDER BY reward DESC, steps, episode LIMIT 5\"")
    print(f"  tracelab trace {run} --episode {ep} --from {last} --to {last}            # its last step")
    if row:
        print(f"  tracelab why {run} {shlex.quote(row[0])} --episode {ep} --at {row[1]}   # why is it true?")
    print(f"  tracelab tui {run}")
    print(f"  tracelab replay {run} --episode {ep} --save replay.rrd")
