"""`tracelab eval POLICY`: play a saved policy against the scripted opponent and count the outcomes both
ways (tracelab's and the method's; tracelab/train/evaluate.py), side by side or as JSON. With --run,
every game is traced into a new run."""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from tracelab.bench.common import format_table
from tracelab.commands._progress import Progress, progress
from tracelab.commands._worlds import env_source_of, load_scenario_arg
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar import scenario_spec
from tracelab.errors import UserError, store_errors
from tracelab.game.facts import GAME_RULES
from tracelab.game.scenario import BOARD
from tracelab.store import TraceWriter
from tracelab.train.env_policy import (
    ENV_FORMAT,
    OneAgentGridWarPolicy,
    evaluate_env,
    evaluate_team,
    load_env_policy,
    load_policy,
    policy_format,
    policy_scenario,
    read_policy_spec,
)
from tracelab.train.evaluate import METHOD_CUT, comparison_rows, evaluate, evaluate_into
from tracelab.train.experiments.stats import wilson


def run(args: argparse.Namespace) -> int:

    with store_errors():
        trained_on_env = policy_format(args.policy) == ENV_FORMAT
    if args.env is not None or args.env_arg or trained_on_env:
        return _run_env(args)
    if not 0.0 <= args.opponent_p <= 1.0:
        raise UserError(f"--opponent-p must be in [0, 1], got {args.opponent_p}")
    with store_errors():  # a policy or scenario that does not load
        spec = read_policy_spec(args.policy)
        scenario = load_scenario_arg(args.scenario) if args.scenario else policy_scenario(spec)
        policy = load_policy(args.policy, scenario)
    source = _spec_source(args, policy, scenario)
    if source is not None:
        return _run_spec(args, policy, scenario, source)
    with progress(f"evaluating on {scenario.name}", total=args.games, unit="games") as bar:
        result = _evaluate(args, policy, scenario, spec, _counting(bar))
    if args.json:
        json.dump({"policy": str(args.policy), "scenario": scenario.name, "backend": args.backend,
                   "opponent_p": args.opponent_p, "seed": args.seed, "run": args.run, **result.to_dict()},
                  sys.stdout, indent=1)
        print()
    else:
        _table(result, args, scenario.name)
    return 0


def _spec_source(args: argparse.Namespace, policy, scenario):
    """The EnvSource of the scenario's spec where eval plays the GridWar policy through it (untraced, the
    rules backend), else None: RuleSim's evaluate plays it (--run, --backend reference, and scenarios no
    spec plays, until the trainer writes policies of specs)."""
    if args.run is not None or args.backend != "rules":
        return None
    try:
        return EnvSource(*scenario_spec(scenario, policy.stack_previous, args.opponent_p))
    except ValueError:
        return None


def _run_spec(args: argparse.Namespace, policy, scenario, source) -> int:
    """A GridWar policy played greedily on its scenario's spec (rules/gridworld/war*.toml): one agent in
    --num-envs worlds stepped together, a team one world at a time."""
    with progress(f"evaluating on {scenario.name}", total=args.games, unit="games") as bar:
        if scenario.agents_per_team == 1:
            result = evaluate_env(OneAgentGridWarPolicy(policy), source, args.games, args.seed, args.envs,
                                  lambda _: bar.advance(1))
        else:
            result = evaluate_team(policy, source, args.games, args.seed, lambda _: bar.advance(1))
    if args.json:
        json.dump({"policy": str(args.policy), "scenario": scenario.name, "opponent_p": args.opponent_p,
                   "seed": args.seed, "env": source.to_json(), **result.to_dict()}, sys.stdout, indent=1)
        print()
        return 0
    print(f"{args.policy} on {scenario.name} (its spec, {source.name}), against the scripted opponent "
          f"(p={args.opponent_p}), seed {args.seed}")
    _env_table(result)
    return 0


def _run_env(args: argparse.Namespace) -> int:
    """eval --env: a policy of train --env, played greedily on the env it was trained on."""
    with store_errors():
        fmt = policy_format(args.policy)
    if fmt is not None and fmt != ENV_FORMAT:  # None: no format to read; the env policy's loader says what is wrong
        raise UserError(f"{args.policy} is a GridWar policy ({fmt}); --env plays policies of train --env")
    if args.env is None:
        raise UserError(f"{args.policy} was trained with train --env: name that env with --env SPEC_OR_ID "
                        f"(and its --env-arg values); its policy.json says which under \"env\"")
    if args.scenario is not None or args.run is not None:
        raise UserError(f"{'--scenario' if args.scenario is not None else '--run'} is GridWar's; eval --env "
                        f"takes --games, --seed, --num-envs, --json")
    source = env_source_of(args)
    with store_errors():
        policy, _ = load_env_policy(args.policy, source)
    with progress(f"evaluating on {source.name}", total=args.games, unit="games") as bar:
        result = evaluate_env(policy, source, args.games, args.seed, args.envs, lambda _: bar.advance(1))
    if args.json:
        json.dump({"policy": str(args.policy), "env": source.to_json(), "seed": args.seed, **result.to_dict()},
                  sys.stdout, indent=1)
        print()
        return 0
    print(f"{args.policy} on {source.describe()}, {result.games} greedy games, seed {args.seed}")
    _env_table(result)
    return 0


def _env_table(result) -> None:
    low, high = wilson(result.successes, result.games)
    print(f"  mean return     {result.mean_return:.3f}")
    print(f"  success rate    {100 * result.success_rate:.1f}% [{100 * low:.1f}%, {100 * high:.1f}%] "
          f"(return > 0; 95% Wilson interval)")
    if result.wins is not None:  # the world declares what a win is ([end] win)
        low, high = wilson(result.wins, result.games)
        print(f"  win rate        {100 * result.wins / result.games:.1f}% [{100 * low:.1f}%, {100 * high:.1f}%] "
              f"({result.wins} won, as the world's [end] win declares)")
        print(f"  outcomes        {result.wins} won, {result.losses} lost, {result.draws} drawn (ended by "
              f"neither), {result.truncated} truncated; the method's win rate is the win rate (a game cut "
              f"short is lost)")
    print(f"  ended           {result.terminated} terminated, {result.truncated} truncated; mean "
          f"{result.metrics('')['mean_steps']:.1f} steps")


def _counting(bar: Progress):
    """A per-game callback that advances the bar and shows the win rate so far."""
    wins = 0

    def ended(game) -> None:
        nonlocal wins
        wins += game.outcome == "win"
        bar.advance(1)
        bar.set_fields(**{"win rate": f"{100 * wins / bar.completed:.1f}%"})
    return ended


def _evaluate(args: argparse.Namespace, policy, scenario, spec, on_game):
    if args.run is None:
        return evaluate(policy, scenario, games=args.games, backend=args.backend, seed=args.seed,
                        opponent_p=args.opponent_p, stack_previous=policy.stack_previous,
                        envs=args.envs, on_game=on_game)
    meta = {"command": " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]]),
            "scenario": scenario.name, "seed": args.seed, "rule_files": [str(GAME_RULES)], "board": BOARD,
            "config": {"policy": str(args.policy), "games": args.games, "backend": args.backend,
                       "opponent_p": args.opponent_p, "scenario_toml": scenario.to_toml(),
                       "policy_spec": spec}}
    with store_errors():  # the run directory exists, or another writer holds it
        writer = TraceWriter.open(Path(args.run), meta)
    return evaluate_into(writer, policy, scenario, games=args.games, backend=args.backend, seed=args.seed,
                         opponent_p=args.opponent_p, on_game=on_game)


def _table(result, args: argparse.Namespace, scenario: str) -> None:
    print(f"{args.policy} on {scenario} ({args.backend} backend), {result.games} games against the scripted "
          f"opponent (p={args.opponent_p}), seed {args.seed}")
    rows = [[name, str(a), str(b)] for name, a, b in comparison_rows(result)]
    print(format_table(["", "tracelab", f"method (cut at {METHOD_CUT} steps)"], rows))
    print("method: a win is a capture within 200 steps; cut games count as losses; draws and wins by "
          "elimination are non-wins")
    print("95% CI: Wilson intervals for the win rates, a t-interval over the games for the mean return")
    if args.run:
        run = shlex.quote(args.run)
        print(f"\ngames traced into {args.run}/:")
        print(f"  tracelab sql {run} \"SELECT episode, outcome, steps, reward FROM episodes ORDER BY episode\"")
        print(f"  tracelab trace {run} --episode 0 --from 1 --to 4")
