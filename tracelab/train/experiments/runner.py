"""Training and evaluating for the experiments, on the training API (Trainer, evaluate): one run per
seed, with the final policy evaluated against each opponent setting and those figures written into the
run's own `metrics` (suffix `@p0.3`, `@p0.7`, docs/training.md), so `tracelab sql` sees them."""
from __future__ import annotations

import shlex
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from tracelab.game.facts import GAME_RULES
from tracelab.game.scenario import BOARD, Scenario
from tracelab.store import TraceWriter
from tracelab.store.queries import get_query
from tracelab.store.reader import fetch_arrow, open_run, query_readonly, retrying
from tracelab.train.config import TrainConfig
from tracelab.train.evaluate import EvalResult, evaluate, evaluate_into
from tracelab.train.env_policy import BEST_POLICY_DIR, Policy, load_policy

if TYPE_CHECKING:
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.env_policy import EnvEvalResult
    from tracelab.train.loop import Trainer
    from tracelab.train.tensorboard import MetricSink

WORLD_P = 0.0  # a world other than GridWar has no opponent setting: its final evaluation's key
FINAL_EVAL_ROUND = 1_000_000  # seeds of the final evaluations: apart from the training's rounds


@dataclass
class SeedRun:
    """One trained seed: its run, its final evaluations per opponent p, its policy."""
    seed: int
    run_dir: Path
    steps: int
    status: str
    final: dict[float, EvalResult] = field(default_factory=dict)
    policy_dir: Path | None = None
    best: dict[float, EvalResult] = field(default_factory=dict)  # the kept best policy's (RUN/policy-best)
    best_step: int | None = None                                 # the step it was saved at
    wall_s: float = 0.0


CLOSE_WAIT_S = 60  # how long a stopped or cancelled training may take to close its run


def p_suffix(p: float) -> str:
    return f"@p{p:g}"


def final_eval_seed(seed: int, p: float) -> int:
    return int(np.random.SeedSequence([seed, 3, FINAL_EVAL_ROUND, int(round(p * 1000))]).generate_state(1)[0])


def train_seed(cfg: TrainConfig, scenario: Scenario | EnvSource, run_dir: Path, command: str,
               eval_ps: tuple[float, ...], eval_games: int, metric_sinks: Sequence[MetricSink] = (),
               started: Callable[[Trainer], None] | None = None, rulesim: bool = False) -> SeedRun:
    """Train `cfg` into a new run at `run_dir`, then evaluate the final policy `eval_games` games
    against each opponent p in `eval_ps`, writing `eval/...@pP` metrics at the last step. `metric_sinks`
    receive the training's metrics besides the run; `started` is called with the Trainer before it trains
    (a sweep's trial stops it through it: Trainer.stop_requested). `scenario` an EnvSource: a world other
    than GridWar, trained with train --env's trainer (_world_parts); a GridWar scenario trains through its
    spec as `train --scenario` does (_gridwar_parts), or with `rulesim` through RuleSim's Trainer
    (_rulesim_parts: what the spec path does not train yet, experiments/run.py's RULESIM)."""
    # deferred: torch and the trainers, which reading results and queries does not need
    import torch

    from tracelab.envs.declared.env_source import EnvSource
    parts = _world_parts if isinstance(scenario, EnvSource) else _rulesim_parts if rulesim else _gridwar_parts
    meta, make_trainer, final_evaluation = parts(cfg, scenario, command, eval_ps, eval_games)
    writer = TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    trainer, status = None, "failed"
    t0 = time.perf_counter()
    try:
        trainer = make_trainer(cfg, scenario, writer, run_dir, metric_sinks=metric_sinks)
        if started is not None:
            started(trainer)
        status = trainer.train()
        out = SeedRun(cfg.seed, run_dir, trainer.step, status, policy_dir=run_dir / "policy")
        policies = [("eval/", trainer.policy, out.final)]
        if trainer.best_eval is not None and trainer.best_eval[1] != trainer.step:  # else the final one
            out.best_step = trainer.best_eval[1]
            policies.append(("eval_best/", run_dir / BEST_POLICY_DIR, out.best))
        for prefix, policy, into in policies:  # the same games for both policies: a paired comparison
            for p, result in final_evaluation(trainer, policy).items():
                writer.write_metrics(trainer.step, result.metrics(p_suffix(p), prefix))
                into[p] = result
        out.wall_s = time.perf_counter() - t0
        return out
    except (KeyboardInterrupt, SystemExit):  # Ctrl-C, or SIGTERM from a killed experiment
        status = "interrupted"
        raise
    finally:
        if trainer is not None:
            trainer.close()
        writer.close(status=status)


FinalEvaluation = Callable[[Any, Any], dict[float, EvalResult]]  # (trainer, policy or its folder) -> per p


def _gridwar_parts(cfg: TrainConfig, scenario: Scenario, command: str, eval_ps: tuple[float, ...],
                   eval_games: int) -> tuple[dict[str, Any], Any, FinalEvaluation]:
    """GridWar through its spec, as `train --scenario` trains it: the run meta, EnvTrainer on the scenario's
    GridWar id (evaluating at --eval-p), and the final evaluation against each opponent p of `eval_ps`
    (the same env with that p_toward), counted by the spec's [end] win / loss."""
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.env_policy import evaluate_env, load_env_policy
    from tracelab.train.env_trainer import EnvTrainer, env_run_meta, gridwar_sources

    source, eval_source = gridwar_sources(cfg, scenario)
    meta = env_run_meta(cfg, source, f"tracelab train (from: {command})", None, scenario)
    meta["config"]["eval_env"] = eval_source.to_json()

    def make_trainer(cfg: TrainConfig, _: Scenario, *args: Any, **kw: Any) -> EnvTrainer:
        return EnvTrainer(cfg, source, *args, eval_source=eval_source, **kw)

    def final_evaluation(trainer: Any, policy: Any) -> dict[float, EvalResult]:
        if isinstance(policy, Path):
            policy = load_env_policy(policy, source)[0]
        return {p: as_eval_result(evaluate_env(policy, EnvSource(source.name, {**source.kwargs, "p_toward": p}),
                                               eval_games, final_eval_seed(cfg.seed, p), cfg.eval_envs))
                for p in eval_ps}
    return meta, make_trainer, final_evaluation


def _rulesim_parts(cfg: TrainConfig, scenario: Scenario, command: str, eval_ps: tuple[float, ...],
                   eval_games: int) -> tuple[dict[str, Any], Any, FinalEvaluation]:
    """GridWar on RuleSim: the run meta, its Trainer, and the final evaluation against each opponent p of
    `eval_ps`."""
    from tracelab.train.loop import Trainer

    meta = {"command": f"tracelab train (from: {command})", "scenario": scenario.name, "seed": cfg.seed,
            "rule_files": [str(GAME_RULES)], "board": BOARD,
            "config": {**cfg.to_dict(), "scenario_toml": scenario.to_toml(), "resumed_from": None}}

    def final_evaluation(trainer: Any, policy: Any) -> dict[float, EvalResult]:
        if isinstance(policy, Path):
            policy = load_policy(policy, scenario)
        return {p: evaluate(policy, scenario, games=eval_games, backend=cfg.backend, seed=final_eval_seed(cfg.seed, p),
                            opponent_p=p, stack_previous=trainer.stack, envs=cfg.eval_envs) for p in eval_ps}
    return meta, Trainer, final_evaluation


def _world_parts(cfg: TrainConfig, source: EnvSource, command: str, eval_ps: tuple[float, ...],
                 eval_games: int) -> tuple[dict[str, Any], Any, FinalEvaluation]:
    """A world other than GridWar: train --env's run meta and trainer; its final evaluation, `eval_games`
    games counted as the world declares, keyed WORLD_P (it has no opponent setting)."""
    from tracelab.train.env_policy import evaluate_env, load_env_policy
    from tracelab.train.env_trainer import EnvTrainer, env_run_meta

    def final_evaluation(trainer: Any, policy: Any) -> dict[float, EvalResult]:
        if isinstance(policy, Path):
            policy = load_env_policy(policy, source)[0]
        return {WORLD_P: as_eval_result(evaluate_env(policy, source, eval_games, final_eval_seed(cfg.seed, WORLD_P),
                                                     cfg.eval_envs))}
    return env_run_meta(cfg, source, f"tracelab train --env (from: {command})"), EnvTrainer, final_evaluation


def as_eval_result(r: EnvEvalResult) -> EvalResult:
    """An evaluation of any world as GridWar's EvalResult, which the reports read: its declared outcomes
    (none declared: no wins); the method's counting is the world's own (a cut game lost, draws non-wins)."""
    wins = r.wins or 0
    apw = float(np.mean(r.win_steps)) if r.win_steps else None
    return EvalResult(games=r.games, wins=wins, losses=r.losses, draws=r.draws, truncated=r.truncated,
                      mean_return=r.mean_return, actions_per_win=apw, method_wins=wins,
                      method_losses=r.losses + r.truncated, method_non_wins=r.draws, method_actions_per_win=apw)


def traced_games(policy: Policy, scenario: Scenario, run_dir: Path, *, games: int, backend: str, seed: int,
                 opponent_p: float, command: str, about: dict[str, Any]) -> EvalResult:
    """`games` evaluation games of `policy`, every one traced in full into a new run (as `tracelab eval
    --run` does): the saved queries then read only evaluation games."""
    meta = {"command": command, "scenario": scenario.name, "seed": seed, "rule_files": [str(GAME_RULES)],
            "board": BOARD,
            "config": {**about, "games": games, "backend": backend, "opponent_p": opponent_p,
                       "scenario_toml": scenario.to_toml()}}
    return evaluate_into(TraceWriter.open(run_dir, meta), policy, scenario, games=games, backend=backend,
                         seed=seed, opponent_p=opponent_p, metrics_suffix=p_suffix(opponent_p))


def run_query(run_dir: Path, name: str, **params: str) -> list[dict[str, Any]]:
    """A saved query (tracelab/queries/NAME.sql) on a run, through the sandboxed read path."""
    saved = get_query(name)
    con = open_run(run_dir)
    try:
        table = retrying(lambda: fetch_arrow(query_readonly(con, saved.sql, saved.bind(dict(params)))))
    finally:
        con.close()
    return table.to_pylist()


def run_sql(run_dir: Path, sql: str) -> list[dict[str, Any]]:
    """A read-only query on a run, through the sandboxed read path."""
    con = open_run(run_dir)
    try:
        return retrying(lambda: fetch_arrow(query_readonly(con, sql))).to_pylist()
    finally:
        con.close()


def curves(run_dir: Path, names: tuple[str, ...]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """metric name -> (steps, values) of a run, in step order."""
    listed = ", ".join("'" + n.replace("'", "''") + "'" for n in names)
    rows = run_sql(run_dir, f"SELECT name, step, value FROM metrics WHERE name IN ({listed}) ORDER BY step")
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for n in names:
        pts = [(r["step"], r["value"]) for r in rows if r["name"] == n]
        out[n] = (np.array([s for s, _ in pts], float), np.array([v for _, v in pts], float))
    return out


def quoted(argv: list[str]) -> str:
    return " ".join(shlex.quote(a) for a in argv)
