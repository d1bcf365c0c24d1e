"""`tracelab eval POLICY`: play a saved policy against the scripted opponent and count the outcomes both
ways (tracelab's and the method's; tracelab/train/evaluate.py), side by side or as JSON. With --run,
every game is traced into a new run."""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from tracelab.commands._args import add_max_groundings, non_negative_int, positive_int
from tracelab.commands._progress import Progress, progress
from tracelab.commands.train import load_scenario_arg
from tracelab.commands.train import env_source_of
from tracelab.errors import UserError, store_errors
from tracelab.train.experiments.stats import wilson


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="evaluate a saved policy: wins, losses, draws, truncations, and the "
                                    "method's counting side by side")
    p.add_argument("policy", help="a policy directory (policy.json + policy.pt), e.g. RUN/policy")
    p.add_argument("--games", type=positive_int, default=500, help="games to play (default 500)")
    p.add_argument("--scenario", default=None,
                   help="play on this scenario (built-in name or .toml; default: the policy's own)")
    p.add_argument("--backend", choices=("rules", "reference"), default="rules",
                   help="the rule-driven simulator or the hand-written one (default: rules)")
    p.add_argument("--opponent-p", type=float, default=0.3,
                   help="the opponent's probability of a move towards red's base (default 0.3, the "
                        "method's evaluation)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the games (default 0)")
    p.add_argument("--num-envs", dest="envs", type=positive_int, default=64,
                   help="worlds stepped together (default 64, as train's --eval-envs)")
    p.add_argument("--envs", dest="envs", type=positive_int, help=argparse.SUPPRESS)  # the earlier name
    p.add_argument("--run", default=None, help="trace every game into this new run directory")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.add_argument("--env", default=None, metavar="SPEC_OR_ID",
                   help="play a policy trained with train --env on that env (the same id or spec file and "
                        "--env-arg values it was trained with)")
    p.add_argument("--env-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="a keyword argument of --env (repeatable), as train --env-arg")
    add_max_groundings(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # deferred: not needed to build the CLI's parser (`tracelab --help` imports every command)
    from tracelab.train.env_policy import load_policy, policy_scenario, read_policy_spec

    # deferred: loads gymnasium; every command is imported to build the CLI's parser
    from tracelab.train.env_policy import ENV_FORMAT, policy_format
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
    # deferred: loads gymnasium; every command is imported to build the CLI's parser
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.envs.declared.gridwar import scenario_spec
    if args.run is not None or args.backend != "rules":
        return None
    try:
        return EnvSource(*scenario_spec(scenario, policy.stack_previous, args.opponent_p))
    except ValueError:
        return None


def _run_spec(args: argparse.Namespace, policy, scenario, source) -> int:
    """A GridWar policy played greedily on its scenario's spec (rules/gridworld/war*.toml): one agent in
    --num-envs worlds stepped together, a team one world at a time."""
    # deferred: loads gymnasium, numba; every command is imported to build the CLI's parser
    from tracelab.train.env_policy import OneAgentGridWarPolicy, evaluate_env, evaluate_team
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
    # deferred: loads gymnasium; every command is imported to build the CLI's parser
    from tracelab.train.env_policy import evaluate_env, load_env_policy, policy_format, ENV_FORMAT
    with store_errors():
        fmt = policy_format(args.policy)
    if fmt != ENV_FORMAT:
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
    # deferred: loads DuckDB, gymnasium, numba; every command is imported to build the CLI's parser
    from tracelab.train.evaluate import evaluate, evaluate_into
    if args.run is None:
        return evaluate(policy, scenario, games=args.games, backend=args.backend, seed=args.seed,
                        opponent_p=args.opponent_p, stack_previous=policy.stack_previous,
                        envs=args.envs, on_game=on_game)
    # deferred: loads DuckDB; every command is imported to build the CLI's parser
    from tracelab.game.facts import GAME_RULES
    from tracelab.game.scenario import BOARD
    from tracelab.store import TraceWriter
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
    # deferred: loads DuckDB, gymnasium, numba; every command is imported to build the CLI's parser
    from tracelab.bench.common import format_table
    from tracelab.train.evaluate import METHOD_CUT, comparison_rows
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
