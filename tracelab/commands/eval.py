"""`tracelab eval POLICY`: play a saved policy greedily on its world's spec and count the outcomes (the
method's counting where the world declares a win: tracelab/train/env_policy.py's EnvEvalResult), as a table
or as JSON. A policy of train plays the env it was trained on (its tracelab id, or --env and --env-arg);
an older policy of RuleSim's trainer (converted at load: envs/declared/gridwar_scenarios.py) the spec of
its scenario, or --env.
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
from tracelab.commands._worlds import env_source_of
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar_scenarios import (
    METHOD_EVAL_P,
    has_opponent_p,
    load_trained,
    read_rulesim_spec,
    refuse_scenario_flags,
    scenario_world,
    with_opponent_p,
)
from tracelab.envs.declared.play import load_declared, make_declared_env
from tracelab.errors import UserError, store_errors
from tracelab.store import TraceWriter
from tracelab.store.layout import check_new_run_dir
from tracelab.train.env_policy import ENV_FORMAT, evaluate_env, evaluate_in_env, policy_format, recorded_env
from tracelab.train.env_source import declared_spec
from tracelab.train.experiments.stats import wilson


def run(args: argparse.Namespace) -> int:
    if args.backend != "rules":
        raise UserError(f"--backend {args.backend}: eval plays every policy on its world's spec with the rule "
                        f"engine; drop --backend")
    trained_on, source, scenario = _world(args)
    with store_errors():  # a spec that does not load; a policy that does not, or was trained on another world
        spec = declared_spec(source)  # parsed once: the policy's check reads its spaces, the games play it
        policy = load_trained(args.policy, trained_on, spec)
    name = scenario.name if scenario is not None else source.short_name
    with progress(f"evaluating on {name}", total=args.games, unit="games") as bar:
        if args.run is None:
            result = evaluate_env(policy, source, args.games, args.seed, args.envs, lambda _: bar.advance(1), spec)
        else:
            result = _traced(args, policy, source, spec, scenario, lambda _: bar.advance(1))
    if args.json:
        about = {"policy": str(args.policy), **({"scenario": scenario.name} if scenario is not None else {}),
                 "seed": args.seed, "env": source.to_json(), "run": args.run}
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


def _world(args: argparse.Namespace) -> tuple[EnvSource, EnvSource, Any]:
    """(the env the policy is loaded on, the one it plays, the war game's scenario or None): --env (and
    --env-arg); else a policy of train on one of tracelab's ids plays that id (a scripted opponent at
    --opponent-p, the method's p by default); a policy of train on a spec file needs --env; an older policy
    of RuleSim's trainer plays its scenario's spec, or --scenario's, against the opponent at --opponent-p
    (scenario_world)."""
    with store_errors():  # a policy.json that does not load
        fmt = policy_format(args.policy)
        given = args.env is not None or bool(args.env_arg)
        recorded = recorded_env(args.policy) if fmt == ENV_FORMAT and not given else None
    if fmt != ENV_FORMAT and not given:  # an older policy of RuleSim's trainer: its scenario's spec
        with store_errors():  # a policy or scenario that does not load
            scenario, source = scenario_world(args, read_rulesim_spec(args.policy), METHOD_EVAL_P)
        return source, source, scenario
    refuse_scenario_flags(args, "a policy of train plays the env it was trained on (--env, --env-arg)",
                          ("scenario",))
    if recorded is None and args.env is None:
        raise UserError(f"{args.policy} was trained with train --env on a spec file: name that env with --env "
                        f"SPEC_OR_ID (and its --env-arg values); its policy.json says which under \"env\"")
    source = recorded or env_source_of(args)
    p = METHOD_EVAL_P if args.opponent_p is None and recorded and has_opponent_p(source) else args.opponent_p
    return source, with_opponent_p(source, p), None  # refused for a world with no scripted opponent


def _traced(args: argparse.Namespace, policy: Any, source: EnvSource, spec: Any, scenario: Any, on_game: Any) -> Any:
    """Every game, one at a time, traced into the new run --run (its world, the policy's decisions, the
    reward terms; begin info `{"kind": "eval", "params": the world's params}`: external_eval.eval_info, as a
    training's traced evaluations). `spec`: the world's WorldSpec (None: not a declared world, refused)."""
    from tracelab.train.external_eval import eval_info
    run_dir = Path(args.run)
    with store_errors():
        check_new_run_dir(run_dir)
        spec = spec if spec is not None else load_declared(source)
        writer = TraceWriter.open(run_dir, _run_meta(args, source, spec, scenario))
    with recording_into(writer, run_dir):
        env = make_declared_env(source, spec, trace_writer=writer)
        env.unwrapped.trace_info(eval_info(source))
        try:
            result = evaluate_in_env(policy, env, args.games, args.seed, on_game)
        except BaseException:
            env.unwrapped.close(status="interrupted")
            raise
        env.close()  # the traced env closes its run: the last rows and episode ends are written
    return result


def _run_meta(args: argparse.Namespace, source: EnvSource, spec: Any, scenario: Any) -> dict[str, Any]:
    """The run's meta: the command, the world as a traced training's evaluations describe it
    (external_eval.DeclaredTarget), the policy and the games; the war game's scenario by name and TOML."""
    from tracelab.train.external_eval import DeclaredTarget
    described = DeclaredTarget(source, spec).run_meta()
    config = {**described["config"], "policy": str(args.policy), "games": args.games}
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
