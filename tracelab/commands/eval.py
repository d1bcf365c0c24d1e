"""`tracelab eval POLICY`: play a saved policy greedily on its world's spec and count the outcomes (the
method's counting where the world declares a win: tracelab/train/env_policy.py's EnvEvalResult), as a table
or as JSON. A policy of train plays the env it was trained on (its tracelab id, or --env and --env-arg);
an older GridWar policy (RuleSim's format, converted at load) its scenario's spec (rules/gridworld/war*.toml)
or --env.
With --run, every game is traced into a new run, the policy's decisions and the reward terms included."""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path
from typing import Any

from tracelab.commands._progress import progress
from tracelab.commands._recording import recording_into
from tracelab.commands._worlds import env_source_of, load_scenario_arg
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar import GRIDWAR_SPEC_IDS, WAR_ADVANCED_2V2, WAR_NONMARKOV, WAR_SPEC, scenario_env
from tracelab.envs.declared.play import load_declared, make_declared_env
from tracelab.errors import UserError, store_errors
from tracelab.store import TraceWriter
from tracelab.store.layout import check_new_run_dir
from tracelab.train.env_policy import (
    ENV_FORMAT,
    evaluate_env,
    evaluate_in_env,
    load_trained,
    policy_format,
    read_rulesim_spec,
    recorded_env,
    rulesim_scenario,
)
from tracelab.train.experiments.stats import wilson

DEFAULT_OPPONENT_P = 0.3  # the method's evaluation
GRIDWAR_SPECS = {str(WAR_SPEC), str(WAR_NONMARKOV), str(WAR_ADVANCED_2V2)}


def run(args: argparse.Namespace) -> int:
    if args.opponent_p is not None and not 0.0 <= args.opponent_p <= 1.0:
        raise UserError(f"--opponent-p must be in [0, 1], got {args.opponent_p}")
    if args.backend != "rules":
        raise UserError(f"--backend {args.backend}: eval plays every policy on its world's spec (GridWar's: "
                        f"rules/gridworld/war.toml) with the rule engine; drop --backend")
    source, scenario, recorded = _world(args)
    with store_errors():  # a policy that does not load, or was trained on another world
        policy = load_trained(args.policy, source)
    # GridWar's opponent at --opponent-p (a policy of train on its own id: at the method's p by default)
    p = DEFAULT_OPPONENT_P if args.opponent_p is None and recorded and _is_gridwar(source) else args.opponent_p
    if scenario is None and p is not None:
        source = EnvSource(source.name, {**source.kwargs, "p_toward": p})
    name = scenario.name if scenario is not None else source.short_name
    with progress(f"evaluating on {name}", total=args.games, unit="games") as bar:
        if args.run is None:
            result = evaluate_env(policy, source, args.games, args.seed, args.envs, lambda _: bar.advance(1))
        else:
            result = _traced(args, policy, source, scenario, lambda _: bar.advance(1))
    if args.json:
        about = {"policy": str(args.policy), **({"scenario": scenario.name} if scenario is not None else {}),
                 "opponent_p": _opponent_p(source), "seed": args.seed, "env": source.to_json(), "run": args.run}
        json.dump({**about, **result.to_dict()}, sys.stdout, indent=1)
        print()
        return 0
    print(f"{args.policy} on {source.describe()}, {result.games} greedy games, seed {args.seed}")
    _table(result)
    if args.run is not None:
        run = shlex.quote(args.run)
        print(f"\ngames traced into {args.run}/:")
        print(f"  tracelab sql {run} \"SELECT episode, outcome, steps, reward FROM episodes ORDER BY episode\"")
        print(f"  tracelab trace {run} --episode 0 --from 1 --to 4")
    return 0


def _world(args: argparse.Namespace) -> tuple[EnvSource, Any, bool]:
    """(the env the policy plays, GridWar's scenario or None, whether the env is the one the policy recorded):
    --env (and --env-arg); else a policy of train on one of tracelab's ids plays that id; a policy of train on
    a spec file needs --env; an older GridWar policy plays its scenario's spec (_scenario_world)."""
    with store_errors():  # a policy.json that does not load
        fmt = policy_format(args.policy)
        given = args.env is not None or bool(args.env_arg)
        recorded = recorded_env(args.policy) if fmt == ENV_FORMAT and not given else None
    if fmt != ENV_FORMAT and not given:
        return (*_scenario_world(args), False)
    if args.scenario is not None:
        raise UserError("--scenario is GridWar's earlier policies'; a policy of train plays the env it was "
                        "trained on (--env, --env-arg)")
    if recorded is None and args.env is None:
        raise UserError(f"{args.policy} was trained with train --env on a spec file: name that env with --env "
                        f"SPEC_OR_ID (and its --env-arg values); its policy.json says which under \"env\"")
    source = recorded or env_source_of(args)
    if args.opponent_p is not None and not _is_gridwar(source):
        raise UserError(f"--opponent-p is GridWar's scripted opponent's; {source.describe()} has none")
    return source, None, recorded is not None


def _is_gridwar(source: EnvSource) -> bool:
    return source.name in GRIDWAR_SPEC_IDS or source.name in GRIDWAR_SPECS


def _scenario_world(args: argparse.Namespace) -> tuple[EnvSource, Any]:
    """The spec that plays the scenario of a policy of GridWar's earlier trainer (RuleSim's format), or
    --scenario, against the opponent at --opponent-p, and that scenario; a policy that does not convert, or
    a scenario no spec plays, is refused in one line saying how to go on."""
    with store_errors():  # a policy or scenario that does not load
        spec = read_rulesim_spec(args.policy)
        scenario = load_scenario_arg(args.scenario) if args.scenario else rulesim_scenario(spec)
    p = DEFAULT_OPPONENT_P if args.opponent_p is None else args.opponent_p
    try:
        name, params = scenario_env(scenario, p, spec["observation"]["stack_previous"])
    except UserError as e:
        raise UserError(f"{args.policy} (a GridWar policy of RuleSim's trainer) cannot be played: {e}") from None
    return EnvSource(name, {**params, "p_toward": p}), scenario


def _opponent_p(source: EnvSource) -> float | None:
    return source.kwargs.get("p_toward")


def _traced(args: argparse.Namespace, policy: Any, source: EnvSource, scenario: Any, on_game: Any) -> Any:
    """Every game, one at a time, traced into the new run --run (its world, the policy's decisions, the
    reward terms; begin info `{"kind": "eval", "opponent_p": P}`)."""
    run_dir = Path(args.run)
    with store_errors():
        check_new_run_dir(run_dir)
        spec = load_declared(source)
        writer = TraceWriter.open(run_dir, _run_meta(args, source, spec, scenario))
    with recording_into(writer, run_dir):
        env = make_declared_env(source, spec, trace_writer=writer)
        env.unwrapped.trace_info({"kind": "eval", **({"opponent_p": _opponent_p(source)}
                                                      if _opponent_p(source) is not None else {})})
        try:
            result = evaluate_in_env(policy, env, args.games, args.seed, on_game)
        except BaseException:
            env.unwrapped.close(status="interrupted")
            raise
        env.close()  # the traced env closes its run: the last rows and episode ends are written
    return result


def _run_meta(args: argparse.Namespace, source: EnvSource, spec: Any, scenario: Any) -> dict[str, Any]:
    """The run's meta: the command, the world as a traced training's evaluations describe it
    (external_eval.DeclaredTarget), the policy and the games; GridWar's scenario by name and TOML."""
    from tracelab.train.external_eval import DeclaredTarget
    described = DeclaredTarget(source, spec).run_meta()
    config = {**described["config"], "policy": str(args.policy), "games": args.games,
              "opponent_p": _opponent_p(source)}
    meta = {"command": " ".join(shlex.quote(a) for a in ["tracelab", *sys.argv[1:]]), "seed": args.seed,
            "scenario": described["scenario"], "rule_files": described["rule_files"], "config": config}
    if scenario is not None:
        meta["scenario"] = scenario.name
        config["scenario_toml"] = scenario.to_toml()
    return meta


def _table(result: Any) -> None:
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
