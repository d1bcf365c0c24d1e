"""`tracelab train --env SPEC_OR_ID [--env-arg key=value ...]`: DQN on a gymnasium env (a declared world
or any registered env with Discrete actions), with train's DQN flags, logged into a run as GridWar's
training is (metrics, episodes, RUN/policy/, RUN/policy-best/). tracelab/train/env_trainer.py holds the
loop."""
from __future__ import annotations

import argparse
import shlex
import signal
import sys
import time
from pathlib import Path
from typing import Any

from tracelab.errors import UserError, store_errors

# TrainConfig fields that describe GridWar (its scenario, teams, opponent, simulator): refused with --env
GRIDWAR_ONLY = ("scenario", "non_markov", "split_networks", "slow_every_step", "agents", "backend", "kernel",
                "opponent_p", "eval_p", "explore_scripted", "trace_eval_games")


def env_source_of(args: argparse.Namespace) -> Any:
    from tracelab.envs.declared.env_source import EnvSource, parse_env_args
    if args.env is None:
        raise UserError("--env-arg needs --env SPEC_OR_ID")
    return EnvSource.given(args.env, parse_env_args(args.env_arg))


def refuse_env_resume(run: Path) -> None:
    """--resume of a train --env run: one line saying it keeps no checkpoint yet, and what still works."""
    from tracelab.store.meta import current_meta
    from tracelab.envs.declared.env_source import env_source_from_json
    try:
        env = current_meta(run).get("config", {}).get("env")
    except (OSError, ValueError, AttributeError):
        return  # not a run (or not one of these): load_checkpoint says what it is
    if env is not None:
        source = env_source_from_json(env, str(run / "meta.json"))
        raise UserError(f"{run} trained with --env {source.describe()}: an --env run keeps no checkpoint yet, "
                        f"so it cannot be resumed; its policy plays: tracelab eval {shlex.quote(str(run))}/policy "
                        f"--env {source.describe()}")


def run_env(args: argparse.Namespace, given: dict[str, Any], limit: Any) -> int:
    from tracelab.train.config import METHOD_REWARD_SCALE, TrainConfig, flag_of
    from tracelab.train.memory import FLOAT
    from tracelab.train.replay import row_length

    source = env_source_of(args)
    if args.resume:
        raise UserError(f"--resume continues GridWar runs; an --env run keeps no checkpoint yet: train "
                        f"{args.env} again (or evaluate RUN/policy with tracelab eval --env)")
    gridwar = [flag_of(k) for k in GRIDWAR_ONLY if k in given]
    if gridwar:
        raise UserError(f"{', '.join(gridwar)} describe{'s' if len(gridwar) == 1 else ''} GridWar; "
                        f"--env {args.env} takes the DQN flags only")
    # gymnasium's envs reward about 1 already: the scale that learns the game's hundreds would shrink them
    # 100x, so an env is trained at its own scale unless told (docs/experiments/toytext.md)
    given.setdefault("reward_scale", METHOD_REWARD_SCALE)
    with store_errors():
        cfg = TrainConfig(**given)
        probe = source.make()  # a bad id, spec or keyword argument fails here, in one line
    try:
        from tracelab.train.env_source import ObservationEncoder, action_count
        encoder = ObservationEncoder(probe.observation_space, args.env)
        n_actions = action_count(probe.action_space, args.env)
    finally:
        probe.close()
    need = cfg.buffer * row_length(encoder.size, n_actions, cfg.mask) * FLOAT
    if need > limit.bytes:
        raise UserError(f"--buffer-size {cfg.buffer:,}: the replay buffer would take {need:,} bytes, over the "
                        f"limit of {limit}")
    if cfg.trace_eval_games > cfg.eval_games:
        cfg.trace_eval_games = 0  # nothing is traced in an --env evaluation
    name = Path(args.env).stem if Path(args.env).suffix == ".toml" else args.env.split("/")[-1]
    run_dir = Path(args.run or f"runs/{args.exp_name or 'train'}-{name}-{time.strftime('%Y%m%d-%H%M%S')}")
    tensorboard = None
    if args.tensorboard:  # checked before training: the install hint, a log directory already used
        from tracelab.train.tensorboard import run_log_dir
        tensorboard = run_log_dir(Path(args.tensorboard), run_dir.resolve().name, appending=False)
    return train_env_into(cfg, source, run_dir, encoder.describe(), tensorboard=tensorboard)


def train_env_into(cfg: Any, source: Any, run_dir: Path, encoding: str, stop_at: int | None = None,
                   tensorboard: Path | None = None) -> int:
    import torch

    from tracelab.store import TraceWriter
    from tracelab.train.config import reward_scale_text
    from tracelab.train.env_trainer import EnvTrainer

    meta = {"command": " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]]),
            "scenario": source.name, "seed": cfg.seed,
            "config": {**cfg.to_dict(), "env": source.to_json()}}
    if not meta["command"].startswith("tracelab train"):
        meta["command"] = "tracelab train --env (python: tracelab.commands.train_env.train_env_into)"
    with store_errors():
        writer = TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    was_deterministic = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(cfg.torch_deterministic)
    print(f"training on {source.describe()} ({encoding} observations, {cfg.envs} worlds in gymnasium's "
          f"SyncVectorEnv, {reward_scale_text(cfg.reward_scale)}) for {cfg.steps:,} steps; run: {run_dir}",
          file=sys.stderr)
    trainer = sink = None
    status = "failed"
    previous = signal.getsignal(signal.SIGINT)
    try:
        if tensorboard is not None:
            from tracelab.train.tensorboard import TensorBoardSink
            sink = TensorBoardSink(tensorboard)
        trainer = EnvTrainer(cfg, source, writer, run_dir, metric_sinks=[sink] if sink else [])
        if trainer.learner_note:
            print(f"note: {trainer.learner_note}", file=sys.stderr)

        from tracelab.commands._training import train_until_stopped
        status = train_until_stopped(trainer, cfg.steps, stop_at, "the policy", lambda fig: {
            "ret": "-" if fig["mean_return"] is None else f"{fig['mean_return']:.2f}"})
    except KeyboardInterrupt:
        status = "interrupted"
    finally:
        signal.signal(signal.SIGINT, previous)
        torch.use_deterministic_algorithms(was_deterministic)
        if trainer is not None:
            trainer.close()
        if sink is not None:
            sink.close()
        writer.close(status=status)
    if trainer is not None:
        _report(trainer, source, run_dir, status)
    if sink is not None:
        print(f"  tensorboard --logdir {shlex.quote(str(tensorboard.parent))}   # {sink.scalars:,} scalars in "
              f"{tensorboard}/")
    return 0 if status == "finished" else 130


def _report(trainer: Any, source: Any, run_dir: Path, status: str) -> None:
    ev = trainer.last_eval
    print(f"{status} at step {trainer.step:,}" + (
        f"; last evaluation: mean return {ev.mean_return:.3f}, success (return > 0) {ev.successes}/{ev.games} "
        f"({100 * ev.success_rate:.1f}%)" if ev else ""))
    if trainer.best_eval is not None and ev is not None and trainer.best_eval[0] > ev.mean_return:
        print(f"best evaluation at step {trainer.best_eval[1]:,} (mean return {trainer.best_eval[0]:.3f}): its "
              f"policy is kept in {run_dir}/policy-best/")
    run = shlex.quote(str(run_dir))
    print(f"run: {run_dir}/  policy: {run_dir}/policy/")
    print(f"  tracelab sql {run} \"SELECT step, value FROM metrics WHERE name = 'eval/mean_return' ORDER BY step\"")
    if status == "finished":
        print(f"  tracelab eval {run}/policy --env {source.describe()} --games 1000")
