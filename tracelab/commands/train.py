"""`tracelab train`: DQN against the scripted opponent, logged live into a trace-store run
(docs/training.md). Ctrl-C stops cleanly (the run ends `interrupted`, with a checkpoint);
`--resume RUN` continues a run's last checkpoint in the same run (`--run NEW`: into a new one)."""
from __future__ import annotations

import argparse
import dataclasses
import shlex
import sys
from pathlib import Path
from typing import Any

from tracelab.commands._args import ENGINE_KERNELS, add_max_groundings, boolean, byte_size, integer
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
from tracelab.commands.train_env import is_env_run, run_env
from tracelab.errors import UserError, store_errors
from tracelab.train.budget import reward_scale_note, too_short_hint
from tracelab.train.config import LEARNERS, TrainConfig, config_fields, reward_scale_text


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train red with DQN, logging metrics, episodes and traced evaluation "
                                     "games into a run", argument_default=argparse.SUPPRESS)
    for f in config_fields():
        flag, name = "--" + f.flag, f.name
        shown = f.help if f.default is None or isinstance(f.default, bool) else f"{f.help} (default: {f.default})"
        if name == "non_markov":
            p.add_argument("--non-markov", dest="non_markov", action="store_true", help=shown)
            p.add_argument("--markov", dest="non_markov", action="store_false",
                           help="the Markov setup: the current observation only (default)")
            continue
        if name == "torch_deterministic":  # CleanRL's spelling: --torch-deterministic [true|false]
            p.add_argument(flag, dest=name, type=boolean, nargs="?", const=True, metavar="BOOL",
                           help=f"{shown} (default: on)")
            p.add_argument("--no-" + f.flag, dest=name, action="store_false", help=argparse.SUPPRESS)
            continue
        if f.type in ("bool", bool):
            kw: dict[str, Any] = {"action": "store_true"}
        elif name == "backend":
            kw = {"choices": ("rules", "reference")}
        elif name == "kernel":
            kw = {"choices": ENGINE_KERNELS}
        elif name == "learner":
            kw = {"choices": LEARNERS}
        else:
            conv = {"int": integer, "float": float, "str": str, "int | None": integer}.get(str(f.type), str)
            kw = {"type": conv, "metavar": f.flag.upper().replace("-", "_")}
        p.add_argument(flag, dest=name, help=shown, **kw)
        if f.alias:  # the field's own name, as earlier versions and docs wrote it: accepted, not listed
            p.add_argument("--" + f.alias, dest=name, help=argparse.SUPPRESS, **kw)
    p.add_argument("--exp-name", default=None, type=run_name, metavar="NAME",
                   help="name the run runs/NAME-<scenario>-<time> (default NAME: train)")
    p.add_argument("--run", default=None, help="run directory (default runs/train-<scenario>-<time>)")
    p.add_argument("--resume", default=None, metavar="RUN",
                   help="continue RUN's last checkpoint in RUN itself (its config; --total-timesteps may "
                        "raise the budget); with --run NEW, into a new run NEW instead")
    p.add_argument("--max-memory", type=byte_size, default=None, metavar="SIZE",
                   help="refuse a run whose networks, replay buffers and worlds are estimated to need more "
                        "(e.g. 12G; default: half of this machine's memory)")
    p.add_argument("--tensorboard", default=None, metavar="DIR",
                   help="also write the metrics as TensorBoard event files into DIR/<run name>/ while training "
                        "(needs the tensorboard package: pip install 'tracelab[tensorboard]')")
    p.add_argument("--env", default=None, metavar="SPEC_OR_ID",
                   help="train on this gymnasium env instead of GridWar: a registered id "
                        "(tracelab/FrozenLake-v1, tracelab/Taxi-v4, ...) or a spec file (docs/worlds.md); a "
                        "Discrete observation is one-hot encoded for the network (docs/training.md)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of --env (repeatable), its value read as TOML: is_slippery=false")
    add_max_groundings(p)
    p.set_defaults(func=run)


def run_name(text: str) -> str:
    """--exp-name: a name, not a path (the run goes under runs/)."""
    if not text or "/" in text or "\\" in text or text in (".", ".."):
        raise argparse.ArgumentTypeError(f"expected a name without '/', got {text!r} (--run takes a path)")
    return text


def load_scenario_arg(text: str, agents: int | None = None) -> Any:
    """A built-in scenario name or a .toml file, with `agents` per team if given."""
    # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
    from tracelab.game.scenario import builtin_scenario, builtin_scenario_names, load_scenario
    sc = builtin_scenario(text) if text in builtin_scenario_names() else load_scenario(text)
    if agents is not None and agents != sc.agents_per_team:
        sc = dataclasses.replace(sc, agents_per_team=agents, red_starts=None, blue_starts=None)
    return sc


def run(args: argparse.Namespace) -> int:
    # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
    from tracelab.train.memory import check_training_memory, memory_limit

    # --max-memory and --max-groundings are no training settings (cli.main applies the second): not in the
    # config, free with --resume; argv is the command line cli.main keeps
    given = {k: v for k, v in vars(args).items()
             if k not in ("func", "command", "argv", "run", "resume", "max_memory", "max_groundings", "exp_name",
                          "tensorboard", "env", "env_arg")}
    limit = memory_limit(args.max_memory, "--max-memory")
    if args.env is not None or args.env_arg or (args.resume and is_env_run(Path(args.resume))):
        return run_env(args, given, limit)
    state = None
    with store_errors():  # a bad value in the config or a checkpoint that does not load
        if args.resume:
            # deferred: loads torch; every command is imported to build the CLI's parser
            from tracelab.train.checkpoint import checkpoint_config, checkpoint_scenario, load_checkpoint
            check_resume_flags(given)
            state = load_checkpoint(args.resume, limit)
            cfg = dataclasses.replace(checkpoint_config(state), **given)
            check_budget(args.resume, state["step"], cfg.steps, "steps" in given)
            scenario = checkpoint_scenario(state)
        else:
            cfg = TrainConfig(**given)
            scenario = load_scenario_arg(cfg.scenario, cfg.agents)
        check_training_memory(cfg, scenario, limit)  # before anything is built
    if cfg.non_markov and not scenario.is_non_markov:
        print(f"note: scenario {scenario.name!r} has no slow agent: --non-markov only stacks the previous "
              f"observation", file=sys.stderr)
    if cfg.trace_eval_games > cfg.eval_games:
        raise UserError(f"--trace-eval-games ({cfg.trace_eval_games}) exceeds --eval-games "
                        f"({cfg.eval_games})")
    run_dir, same_run, tensorboard = where_to_train(args, state is not None, scenario.name)
    return train_into(cfg, scenario, run_dir, state, resumed_from=args.resume, same_run=same_run,
                      tensorboard=tensorboard)


def train_into(cfg: Any, scenario: Any, run_dir: Path, state: dict | None = None,
               resumed_from: str | None = None, stop_at: int | None = None, same_run: bool = False,
               tensorboard: Path | None = None) -> int:
    """Train into a new run at `run_dir` (from a checkpoint `state` if given; `same_run`: the checkpoint's
    own run, `run_dir`, continues); returns the exit status. `stop_at`: stop there as Ctrl-C would (tests).
    `tensorboard`: a log directory that also receives the metrics (tracelab.train.tensorboard)."""
    # deferred: loads torch; every command is imported to build the CLI's parser
    import torch

    # deferred: loads DuckDB, torch; every command is imported to build the CLI's parser
    from tracelab.game.facts import GAME_RULES
    from tracelab.game.scenario import BOARD
    from tracelab.store import TraceWriter
    from tracelab.train.checkpoint import restore
    # deferred: loads DuckDB, gymnasium, numba, torch; every command is imported to build the CLI's parser
    from tracelab.train.loop import Trainer

    meta = {"command": " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]]),
            "scenario": scenario.name, "seed": cfg.seed, "rule_files": [str(GAME_RULES)], "board": BOARD,
            "config": {**cfg.to_dict(), "scenario_toml": scenario.to_toml(),
                       "resumed_from": None if state is None else {"run": resumed_from, "step": state["step"]}}}
    if not meta["command"].startswith("tracelab train"):  # called from Python: say what it stands for
        meta["command"] = "tracelab train (python: tracelab.commands.train.train_into)"
    with store_errors():  # the run directory exists, or another writer holds it
        writer = reopen_run(run_dir, cfg, state["step"], meta["command"]) if same_run else \
            TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    kernel = '' if cfg.kernel == 'auto' else f', {cfg.kernel} kernel'
    print(f"training {scenario.name} ({scenario.agents_per_team}v{scenario.agents_per_team}, "
          f"{'non-Markov' if cfg.non_markov else 'Markov'}, {cfg.backend} backend{kernel}, {cfg.envs} worlds, "
          f"{reward_scale_text(cfg.reward_scale)}) for {cfg.steps:,} steps with {cfg.learner_text()}; "
          f"torch on {torch.get_num_threads()} "
          f"CPU thread{'s' if torch.get_num_threads() != 1 else ''} (--threads); run: {run_dir}", file=sys.stderr)
    note = reward_scale_note(max(abs(v) for v in dataclasses.asdict(scenario.rewards).values()), cfg.reward_scale)
    if note:
        print(f"note: {note}", file=sys.stderr)
    purge_step = state["step"] if same_run else None
    with training_session(writer, cfg.torch_deterministic, tensorboard, purge_step) as session:
        session.trainer = trainer = Trainer(cfg, scenario, writer, run_dir, metric_sinks=session.metric_sinks)
        if state is not None:
            with store_errors():  # games that do not replay to their observations: another simulator
                restore(trainer, state)
            if same_run:
                trainer.renumber_games(writer.next_free_episode)
            say_resumed(trainer, writer, run_dir, resumed_from, same_run)
        session.status = train_until_stopped(trainer, cfg.steps, stop_at, "a checkpoint", lambda fig: {
            "win": "-" if fig["win_rate"] is None else f"{100 * fig['win_rate']:.1f}%"})
    trainer, sink, status = session.trainer, session.sink, session.status
    _report(trainer, run_dir, status)
    if sink is not None:
        print(f"  tensorboard --logdir {shlex.quote(str(tensorboard.parent))}   # {sink.scalars:,} scalars in "
              f"{tensorboard}/")
    if trainer is not None and trainer.last_eval is not None:
        hint = too_short_hint(trainer.step, trainer.last_eval.wins, scenario.agents_per_team)
        if hint:
            print(f"hint: {hint}", file=sys.stderr)
    say_running_compiles()
    return 0 if status == "finished" else 130


def _report(trainer: Any, run_dir: Path, status: str) -> None:
    if trainer is None:
        return
    ev = trainer.last_eval
    run = shlex.quote(str(run_dir))
    print(f"{status} at step {trainer.step:,}, {reward_scale_text(trainer.cfg.reward_scale)}"
          + (f"; last evaluation: {ev.wins}/{ev.games} wins "
          f"({100 * ev.win_rate:.1f}%), method's counting {100 * ev.method_win_rate:.1f}%" if ev else ""))
    timing = eval_time_line(trainer.metrics)
    if timing:
        print(timing)
    best = trainer.best_eval
    if best is not None and ev is not None and best[0] > ev.method_win_rate:  # training got worse after it
        print(f"best evaluation at step {best[1]:,} (method's counting {100 * best[0]:.1f}%): its policy is "
              f"kept in {run_dir}/policy-best/")
    print(f"run: {run_dir}/  checkpoint: {run_dir}/checkpoint/  policy: {run_dir}/policy/"
          if status == "finished" else f"run: {run_dir}/  checkpoint: {run_dir}/checkpoint/  "
          f"(continue with: tracelab train --resume {run})")
    print(f"  tracelab sql {run} \"SELECT step, value FROM metrics WHERE name = 'eval/win_rate' ORDER BY step\"")
    print(f"  tracelab sql {run} \"SELECT episode, train_step, outcome, steps FROM episodes WHERE kind = 'eval'\"")
    if status == "finished":
        print(f"  tracelab eval {run}/policy --games 500")
        print(f"  tracelab play --policy {run}/policy --episodes 3")
