"""`tracelab play --env SPEC_OR_ID`: games of a world declared in rules (docs/worlds.md), played by a
random policy or a policy `train --env` trained on it (`--policy RUN/policy`), and recorded into a run of
the trace store (tracelab/envs/declared/recording.py): every
change with its cause, the actions and the random draws as the facts they set, one episode per game.
play.py hands over to `run_env` when --env is given."""
from __future__ import annotations

import argparse
import shlex
import time
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.commands._interrupt import CtrlCBetweenSteps
from tracelab.commands._progress import compiling_engine, progress
from tracelab.commands._recording import read_for_hints, recording_into
from tracelab.engine.errors import is_interrupt
from tracelab.errors import UserError, store_errors

# play's flags that belong to the grid game (GridWar) only
GRIDWAR_ONLY = (("scenario", None, "--scenario"), ("opponent_p", None, "--opponent-p"))


def run_env(args: argparse.Namespace) -> int:
    # deferred: loads gymnasium; every command is imported to build the CLI's parser
    from tracelab.envs.declared.env_source import EnvSource, parse_env_args
    from tracelab.envs.declared.play import load_declared

    for attr, default, flag in GRIDWAR_ONLY:
        if getattr(args, attr) != default:
            raise UserError(f"{flag} is the grid game's; --env plays the world its spec declares")
    if args.worlds != 1:
        raise UserError("--num-envs: --env plays one world at a time for now")
    if args.env_arg and args.env is None:
        raise UserError("--env-arg goes with --env")
    source = EnvSource.given(args.env, parse_env_args(args.env_arg))
    spec = load_declared(source)
    if len(spec.agents) != 1:
        raise UserError(f"--env {args.env}: the spec declares {len(spec.agents)} agents; play --env plays "
                        "one (tracelab.envs.declared.parallel_env.DeclaredParallelEnv plays them all)")
    if args.policy == "scripted":
        raise UserError("--policy scripted is the grid game's; --env plays random (the default) or a policy "
                        "train --env trained on that env (RUN/policy)")
    if args.policy not in (None, "random"):
        # deferred: loads gymnasium; every command is imported to build the CLI's parser
        from tracelab.train.env_policy import load_env_policy
        with store_errors():  # a policy that does not load, or was trained on another env
            args.trained, _ = load_env_policy(args.policy, source)
    if args.no_trace:
        _summary(source, spec, _play(source, spec, args, None))
        return 0
    return _record(source, spec, args)


def _record(source: Any, spec: Any, args: argparse.Namespace) -> int:
    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.store import TraceWriter
    from tracelab.store.layout import check_new_run_dir as check_run_dir

    run_dir = Path(args.run or f"runs/play-{source.short_name}-{time.strftime('%Y%m%d-%H%M%S')}")
    check_run_dir(run_dir)
    try:
        with store_errors():  # another process took the directory since the check: a RuntimeError
            writer = TraceWriter.open(run_dir, run_meta(source, spec, args))
    except OSError as e:
        raise UserError(f"cannot create the run directory {run_dir}: {e.strerror or e}") from e
    with recording_into(writer, run_dir):
        stats = _play(source, spec, args, writer)
    _summary(source, spec, stats)
    _what_to_open_env(run_dir, spec)
    return 0


def run_meta(source: Any, spec: Any, args: argparse.Namespace) -> dict[str, Any]:
    """The run's metadata: the command, the env (id or file, its arguments, the spec and the rule files by
    path, size and hash: their texts go in the run's `sources` table), what sets each external fact
    (recording.declared_facts), the board's rows."""
    # deferred: loads DuckDB, gymnasium, numba; every command is imported to build the CLI's parser
    from tracelab.envs.declared.recording import declared_run_config

    spec_path, params = source.declared()
    config = {"env": source.name, "env_id": source.env_id, "spec_path": spec_path,
              "env_args": params, "episodes": args.episodes, "policy": args.policy or "random",
              "kernel": args.kernel, **declared_run_config(spec)}
    return {"command": " ".join(shlex.quote(a) for a in ["tracelab", *args.argv]), "config": config,
            "rule_files": list(spec.program.files), "seed": args.seed}


def _play(source: Any, spec: Any, args: argparse.Namespace, writer: Any) -> dict[str, Any]:
    # deferred: loads gymnasium; every command is imported to build the CLI's parser
    from tracelab.envs.declared.play import make_declared_env, play_episodes, random_policy

    with compiling_engine(busy=f"building {source.short_name}'s rules…", local_trace=writer is not None,
                          phase=None):  # the declared world says what compiles (its library notice)
        env = make_declared_env(source, spec, kernel=args.kernel,
                                **({} if writer is None else {"trace_writer": writer}))
    if getattr(args, "trained", None) is None:
        policy, cap = random_policy(env, args.seed), None
    else:  # greedy: it may walk in circles where the env sets no step limit (CliffWalking)
        # deferred: loads gymnasium; every command is imported to build the CLI's parser
        from tracelab.train.env_policy import EVAL_STEP_CAP, one_env_actor
        policy, cap = one_env_actor(args.trained, env), EVAL_STEP_CAP
    try:
        with CtrlCBetweenSteps() as ctrl_c, \
                progress(f"playing {source.short_name}", total=args.episodes, unit="episodes") as bar:
            def act(obs: Any, info: dict[str, Any]) -> int:
                ctrl_c.check()  # a Ctrl-C stops the game between two steps (see CtrlCBetweenSteps)
                return policy(obs, info)

            stats = play_episodes(env, args.episodes, args.seed, act, on_episode=lambda e: bar.advance(1),
                                  step_cap=cap)
    except BaseException as e:  # the run records how it ended, with what was played until then
        env.unwrapped.close(status="interrupted" if is_interrupt(e) else "failed")
        raise
    env.close()  # a traced env closes its writer: the last rows and episode ends are written
    return stats


def _summary(source: Any, spec: Any, stats: dict[str, Any]) -> None:
    eps = stats["episodes"]
    returns = np.array([e["return"] for e in eps])
    rate = f"{stats['steps'] / stats['seconds']:,.0f} steps/s" if stats["seconds"] > 0 else "too short to time"
    print(f"played {len(eps)} episodes of {source.short_name} ({stats['steps']} steps, {rate})")
    outcomes = [e["outcome"] for e in eps]
    truncated = f"{outcomes.count('truncated')} truncated; mean return {returns.mean():.2f}"
    if spec.win:  # the spec's `[end] win/loss` says what counts, as the grid game's games do
        print(f"{outcomes.count('win')} won, {outcomes.count('loss')} lost, {truncated}")
    else:
        print(f"{int((returns > 0).sum())} with a positive return, {truncated}")


def _what_to_open_env(run_dir: Path, spec: Any) -> None:
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
