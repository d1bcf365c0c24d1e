"""`tracelab train`: DQN on a world, logged live into a trace-store run (docs/training.md): any gymnasium
env (`--env SPEC_OR_ID [--env-arg key=value ...]`), or the war game's scenario (`--scenario NAME`, with its
flags: team size, opponent p, rewards, --non-markov) as the spec id and params it maps to
(envs/declared/gridwar_scenarios.py); both train through EnvTrainer (tracelab/train/env_trainer.py,
checkpoints in env_checkpoint.py). Ctrl-C stops cleanly (the run ends `interrupted`, with a checkpoint);
`--resume RUN` continues a run's last checkpoint in the same run (`--run NEW`: into a new one)."""
from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
from pathlib import Path
from typing import Any

import torch

from tracelab.commands._notices import say_running_compiles
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
from tracelab.commands._worlds import env_source_of
from tracelab.envs.declared.gridwar_scenarios import (
    SCENARIO_FLAGS,
    ScenarioTraining,
    refuse_scenario_flags,
    resumed_scenario,
)
from tracelab.errors import UserError, store_errors
from tracelab.store import TraceWriter
from tracelab.train.config import RETIRED_FLAGS, TrainConfig
from tracelab.train.env_checkpoint import checkpoint_config, checkpoint_env, load_env_checkpoint
from tracelab.train.env_source import probe_env
from tracelab.train.env_trainer import EnvTrainer, env_run_meta
from tracelab.train.memory import check_estimate, env_training_estimate, env_world_bytes, memory_limit
from tracelab.train.qnet import NetSpec
from tracelab.train.reward_scale import METHOD_REWARD_SCALE, reward_scale_text


def run(args: argparse.Namespace) -> int:

    # --max-memory and --max-groundings are no training settings (cli.main applies the second): not in the
    # config, free with --resume; argv is the command line cli.main keeps
    given = {k: v for k, v in vars(args).items()
             if k not in ("func", "command", "argv", "run", "resume", "max_memory", "max_groundings", "exp_name",
                          "tensorboard", "env", "env_arg")}
    retired = sorted(RETIRED_FLAGS.keys() & given.keys())
    if retired:
        raise UserError(f"{retired[0]} is gone: {RETIRED_FLAGS[retired[0]]}; drop the flag")
    limit = memory_limit(args.max_memory, "--max-memory")
    on_env = args.env is not None or bool(args.env_arg)
    source = env_source_of(args) if on_env else None
    world = {k: given.pop(k) for k in SCENARIO_FLAGS if k in given}  # the war game's scenario, as its params
    if on_env:
        refuse_scenario_flags(args, f"--env {args.env} takes the DQN flags only", SCENARIO_FLAGS)
    state, scenario = None, None
    with store_errors():  # a bad value in the config or a checkpoint that does not load
        if args.resume:
            state, cfg, source, scenario = _resumed(args, given, world, source, limit)
        elif on_env:
            # gymnasium's envs reward about 1 already: the scale that learns the game's hundreds would shrink
            # them 100x, so an env is trained at its own scale unless told (docs/experiments/toytext.md)
            given.setdefault("reward_scale", METHOD_REWARD_SCALE)
            cfg = TrainConfig(**given)
        else:
            cfg = TrainConfig(**given)
            scenario = ScenarioTraining.given(world)
            source = scenario.source
        encoder, n_actions, spec = probe_env(source)
    with store_errors():  # --num-envs 1e7 would build ten million worlds before its first step
        check_estimate(env_training_estimate(cfg, NetSpec(encoder.size, cfg.hidden_sizes, n_actions, cfg.dueling),
                                             env_world_bytes(spec)), limit)
    if spec is None:
        cfg.trace_eval_games = 0  # only a world declared in rules is traced
    elif cfg.trace_eval_games > cfg.eval_games:
        raise UserError(f"--trace-eval-games ({cfg.trace_eval_games}) exceeds --eval-games ({cfg.eval_games})")
    run_dir, same_run, tensorboard = where_to_train(args, state is not None,
                                                    source.short_name if scenario is None else scenario.name)
    return train_env_into(cfg, source, run_dir, encoder.describe(), tensorboard=tensorboard, state=state,
                      resumed_from=args.resume, same_run=same_run, scenario=scenario, spec=spec)


def _resumed(args: argparse.Namespace, given: dict[str, Any], world: dict[str, Any], source: Any,
             limit: Any) -> tuple[Any, ...]:
    """--resume: (the checkpoint, its config with the flags given, the env it trains on, the war game's
    scenario training or None: resumed_scenario reads it from the run, on the checkpoint's env)."""
    check_resume_flags({**given, **{k: v for k, v in world.items() if k != "scenario"}})
    raw, recorded = checkpoint_env(args.resume, limit.bytes)
    scenario = None if source is not None else resumed_scenario(args.resume, recorded, world.get("scenario"))
    source = source if scenario is None else scenario.source
    state = load_env_checkpoint(args.resume, source, limit)  # names the env unless given
    cfg = dataclasses.replace(checkpoint_config(state), **given)
    again = "" if scenario is not None else f" --env {source.describe()}"
    check_budget(args.resume, state["step"], cfg.steps, "steps" in given, again)
    return state, cfg, source, scenario


def train_env_into(cfg: Any, source: Any, run_dir: Path, encoding: str, stop_at: int | None = None,
               tensorboard: Path | None = None, state: dict[str, Any] | None = None,
               resumed_from: str | None = None, same_run: bool = False,
               scenario: ScenarioTraining | None = None, spec: Any = None) -> int:
    """Train on `source` into a new run at `run_dir` (from a checkpoint `state` if given; `same_run`: the
    checkpoint's own run, `run_dir`, continues); returns the exit status. `stop_at`: stop there as Ctrl-C
    would (tests). `scenario`: the war game's scenario `source` plays (the run names it and keeps its
    run_config; its evaluations play its eval_source); `tensorboard`: a log directory
    that also receives the metrics (tracelab.train.tensorboard); `spec`: `source`'s WorldSpec if loaded
    already (probe_env's), which the run's meta reads instead of parsing the spec again."""

    meta = env_run_meta(cfg, source, " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]]),
                        None if state is None else {"run": resumed_from, "step": state["step"]}, scenario, spec)
    if not meta["command"].startswith("tracelab train"):  # called from Python: say what it stands for
        meta["command"] = "tracelab train (python: tracelab.commands.train.train_env_into)"
    eval_source = None if scenario is None else scenario.eval_source
    with store_errors():  # the run directory exists, or another writer holds it
        writer = reopen_run(run_dir, cfg, state["step"], meta["command"]) if same_run else \
            TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    purge_step = state["step"] if same_run else None
    with training_session(writer, cfg.torch_deterministic, tensorboard, purge_step) as session:
        session.trainer = trainer = EnvTrainer(cfg, source, writer, run_dir, metric_sinks=session.metric_sinks,
                                               eval_source=eval_source, spec=spec)
        what = source.describe() if scenario is None else scenario.describe()
        kernel = "" if cfg.kernel == "auto" else f", the {cfg.kernel} kernel"
        print(f"training on {what} ({encoding} observations, {cfg.envs} worlds in {type(trainer.env).__name__}"
              f"{kernel}, "
              f"{reward_scale_text(cfg.reward_scale)}) for {cfg.steps:,} steps with {cfg.learner_text()}; "
              f"torch on {torch.get_num_threads()} CPU thread{'s' if torch.get_num_threads() != 1 else ''} "
              f"(--threads); run: {run_dir}", file=sys.stderr)
        if trainer.vector_note:
            print(f"note: {trainer.vector_note}", file=sys.stderr)
        note = None if scenario is None else scenario.reward_note(cfg.reward_scale)
        if note:
            print(f"note: {note}", file=sys.stderr)
        if state is not None:
            with store_errors():  # games that do not replay to their observations: another env
                trainer.load_state(state)
            if same_run:
                trainer.renumber_games(writer.next_free_episode)
            say_resumed(trainer, writer, run_dir, resumed_from, same_run)
        session.status = train_until_stopped(trainer, cfg.steps, stop_at, "a checkpoint", lambda fig: {
            "ret": "-" if fig["mean_return"] is None else f"{fig['mean_return']:.2f}",
            **({} if fig["win_rate"] is None else {"win": f"{100 * fig['win_rate']:.1f}%"})})
    trainer, sink, status = session.trainer, session.sink, session.status
    if trainer is not None:
        _report(trainer, source, run_dir, status, scenario is not None)
        ev = trainer.last_eval
        if scenario is not None and ev is not None and ev.wins is not None:
            hint = scenario.hint(trainer.step, ev.wins)
            if hint:
                print(f"hint: {hint}", file=sys.stderr)
    if sink is not None:
        print(f"  tensorboard --logdir {shlex.quote(str(tensorboard.parent))}   # {sink.scalars:,} scalars in "
              f"{tensorboard}/")
    say_running_compiles()
    return 0 if status == "finished" else 130


def _report(trainer: Any, source: Any, run_dir: Path, status: str, gridwar: bool) -> None:
    ev = trainer.last_eval
    print(f"{status} at step {trainer.step:,}, {reward_scale_text(trainer.cfg.reward_scale)}" + (
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
        print(f"  continue with: tracelab train --resume {run}" + ("" if gridwar else f" --env {source.describe()}"))
    print(f"  tracelab sql {run} \"SELECT step, value FROM metrics WHERE name = 'eval/mean_return' ORDER BY step\"")
    if status == "finished":
        print(f"  tracelab eval {run}/policy --env {source.describe()} --games 1000")
