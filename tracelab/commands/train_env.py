"""`tracelab train --env SPEC_OR_ID [--env-arg key=value ...]`: DQN on a gymnasium env (a declared world
or any registered env with Discrete actions), with train's DQN flags, logged into a run as GridWar's
training is (metrics, episodes, a declared world's traced evaluation games, RUN/policy/, RUN/policy-best/,
RUN/checkpoint/); `--resume RUN --env SPEC_OR_ID` continues it (in RUN, or with --run NEW in a new run) as
train --resume does GridWar's. tracelab/train/env_trainer.py holds the loop, env_checkpoint.py the
checkpoints."""
from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
from pathlib import Path
from typing import Any

from tracelab.commands._training import (
    check_budget,
    check_resume_flags,
    eval_time_line,
    reopen_run,
    say_resumed,
    train_until_stopped,
    training_session,
    where_to_train,
)
from tracelab.errors import UserError, store_errors
from tracelab.train.config import GRIDWAR_ONLY, METHOD_REWARD_SCALE, TrainConfig, flag_of, reward_scale_text


def env_source_of(args: argparse.Namespace) -> Any:
    # deferred: loads gymnasium; every command is imported to build the CLI's parser
    from tracelab.envs.declared.env_source import EnvSource, parse_env_args
    if args.env is None:
        raise UserError("--env-arg needs --env SPEC_OR_ID")
    return EnvSource.given(args.env, parse_env_args(args.env_arg))


def is_env_run(run: Path) -> bool:
    """Whether `run` is a `train --env` run (its meta.json's config names an env)."""
    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.store.meta import current_meta
    try:
        config = current_meta(run).get("config", {})
    except (OSError, ValueError, AttributeError):
        return False  # not a run (or not one of these): load_checkpoint says what it is
    return isinstance(config, dict) and config.get("env") is not None


def run_env(args: argparse.Namespace, given: dict[str, Any], limit: Any) -> int:
    # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
    from tracelab.train.memory import check_estimate, env_training_estimate, env_world_bytes
    from tracelab.train.qnet import NetSpec

    source = env_source_of(args) if args.env is not None or args.env_arg else None
    gridwar = [flag_of(k) for k in GRIDWAR_ONLY if k in given]
    if gridwar:
        raise UserError(f"{', '.join(gridwar)} describe{'s' if len(gridwar) == 1 else ''} GridWar; "
                        f"--env {args.env} takes the DQN flags only")
    state = None
    with store_errors():
        if args.resume:
            # deferred: loads gymnasium, torch; every command is imported to build the CLI's parser
            from tracelab.train.checkpoint import checkpoint_config
            from tracelab.train.env_checkpoint import load_env_checkpoint
            check_resume_flags(given)
            state = load_env_checkpoint(args.resume, source, limit)  # names the env unless given
            cfg = dataclasses.replace(checkpoint_config(state), **given)
            check_budget(args.resume, state["step"], cfg.steps, "steps" in given, f" --env {source.describe()}")
        else:
            # gymnasium's envs reward about 1 already: the scale that learns the game's hundreds would shrink
            # them 100x, so an env is trained at its own scale unless told (docs/experiments/toytext.md)
            given.setdefault("reward_scale", METHOD_REWARD_SCALE)
            cfg = TrainConfig(**given)
        probe = source.make()  # a bad id, spec or keyword argument fails here, in one line
    try:
        # deferred: loads gymnasium; every command is imported to build the CLI's parser
        from tracelab.train.env_source import ObservationEncoder, action_count
        encoder = ObservationEncoder(probe.observation_space, args.env)
        n_actions = action_count(probe.action_space, args.env)
        spec = getattr(probe.unwrapped, "world_spec", None)
        declared = spec is not None
    finally:
        probe.close()
    with store_errors():  # --num-envs 1e7 would build ten million worlds before its first step
        check_estimate(env_training_estimate(cfg, NetSpec(encoder.size, cfg.hidden_sizes, n_actions, cfg.dueling),
                                             env_world_bytes(spec)), limit)
    if not declared:
        cfg.trace_eval_games = 0  # only a world declared in rules is traced
    elif cfg.trace_eval_games > cfg.eval_games:
        raise UserError(f"--trace-eval-games ({cfg.trace_eval_games}) exceeds --eval-games ({cfg.eval_games})")
    run_dir, same_run, tensorboard = where_to_train(args, state is not None, source.short_name)
    return train_env_into(cfg, source, run_dir, encoder.describe(), tensorboard=tensorboard, state=state,
                          resumed_from=args.resume, same_run=same_run)


def train_env_into(cfg: Any, source: Any, run_dir: Path, encoding: str, stop_at: int | None = None,
                   tensorboard: Path | None = None, state: dict[str, Any] | None = None,
                   resumed_from: str | None = None, same_run: bool = False) -> int:
    """Train into a new run at `run_dir` (from a checkpoint `state` if given; `same_run`: the checkpoint's
    own run, `run_dir`, continues); returns the exit status. `stop_at`: stop there as Ctrl-C would (tests)."""
    # deferred: loads torch; every command is imported to build the CLI's parser
    import torch

    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.store import TraceWriter
    # deferred: loads DuckDB, gymnasium, numba, torch; every command is imported to build the CLI's parser
    from tracelab.train.env_trainer import EnvTrainer, env_run_meta

    meta = env_run_meta(cfg, source, " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]]),
                        None if state is None else {"run": resumed_from, "step": state["step"]})
    if not meta["command"].startswith("tracelab train"):
        meta["command"] = "tracelab train --env (python: tracelab.commands.train_env.train_env_into)"
    with store_errors():
        writer = reopen_run(run_dir, cfg, state["step"], meta["command"]) if same_run else \
            TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    purge_step = state["step"] if same_run else None
    with training_session(writer, cfg.torch_deterministic, tensorboard, purge_step) as session:
        session.trainer = trainer = EnvTrainer(cfg, source, writer, run_dir, metric_sinks=session.metric_sinks)
        print(f"training on {source.describe()} ({encoding} observations, {cfg.envs} worlds in "
              f"{type(trainer.env).__name__}, {reward_scale_text(cfg.reward_scale)}) for {cfg.steps:,} steps "
              f"with {cfg.learner_text()}; run: {run_dir}", file=sys.stderr)
        if trainer.vector_note:
            print(f"note: {trainer.vector_note}", file=sys.stderr)
        if state is not None:
            _restore(trainer, state, writer, run_dir, resumed_from, same_run)
        session.status = train_until_stopped(trainer, cfg.steps, stop_at, "a checkpoint", lambda fig: {
            "ret": "-" if fig["mean_return"] is None else f"{fig['mean_return']:.2f}"})
    trainer, sink, status = session.trainer, session.sink, session.status
    if trainer is not None:
        _report(trainer, source, run_dir, status)
    if sink is not None:
        print(f"  tensorboard --logdir {shlex.quote(str(tensorboard.parent))}   # {sink.scalars:,} scalars in "
              f"{tensorboard}/")
    return 0 if status == "finished" else 130


def _restore(trainer: Any, state: dict[str, Any], writer: Any, run_dir: Path, resumed_from: str | None,
             same_run: bool) -> None:
    with store_errors():  # games that do not replay to their observations: another env
        trainer.load_state(state)
    if same_run:
        trainer.renumber_games(writer.next_free_episode)
    say_resumed(trainer, writer, run_dir, resumed_from, same_run)


def _report(trainer: Any, source: Any, run_dir: Path, status: str) -> None:
    ev = trainer.last_eval
    print(f"{status} at step {trainer.step:,}" + (
        f"; last evaluation: mean return {ev.mean_return:.3f}, success (return > 0) {ev.successes}/{ev.games} "
        f"({100 * ev.success_rate:.1f}%)" if ev else "") + (
        f", won {ev.wins}, lost {ev.losses}, drawn {ev.draws}, truncated {ev.truncated} (win rate "
        f"{100 * ev.win_rate:.1f}%)" if ev and ev.counts_wins else ""))
    timing = eval_time_line(trainer.metrics)
    if timing:
        print(timing)
    if trainer.best_eval is not None and ev is not None and trainer.best_eval[0] > ev.selection()[1]:
        metric, _ = ev.selection()
        print(f"best evaluation at step {trainer.best_eval[1]:,} ({metric.removeprefix('eval/')} "
              f"{trainer.best_eval[0]:.3f}): its policy is kept in {run_dir}/policy-best/")
    run = shlex.quote(str(run_dir))
    print(f"run: {run_dir}/  checkpoint: {run_dir}/checkpoint/  policy: {run_dir}/policy/")
    if status != "finished":
        print(f"  continue with: tracelab train --resume {run} --env {source.describe()}")
    print(f"  tracelab sql {run} \"SELECT step, value FROM metrics WHERE name = 'eval/mean_return' ORDER BY step\"")
    if status == "finished":
        print(f"  tracelab eval {run}/policy --env {source.describe()} --games 1000")
