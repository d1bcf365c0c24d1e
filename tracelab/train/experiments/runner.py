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
from tracelab.train.policy import BEST_POLICY_DIR, Policy, load_policy

if TYPE_CHECKING:
    from tracelab.train.loop import Trainer
    from tracelab.train.tensorboard import MetricSink

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


def train_seed(cfg: TrainConfig, scenario: Scenario, run_dir: Path, command: str,
               eval_ps: tuple[float, ...], eval_games: int, metric_sinks: Sequence[MetricSink] = (),
               started: Callable[[Trainer], None] | None = None) -> SeedRun:
    """Train `cfg` into a new run at `run_dir`, then evaluate the final policy `eval_games` games
    against each opponent p in `eval_ps`, writing `eval/...@pP` metrics at the last step. `metric_sinks`
    receive the training's metrics besides the run; `started` is called with the Trainer before it trains
    (a sweep's trial stops it through it: Trainer.stop_requested)."""
    # deferred: torch and the trainer, which reading results and queries does not need
    import torch

    from tracelab.train.loop import Trainer

    meta = {"command": f"tracelab train (from: {command})", "scenario": scenario.name, "seed": cfg.seed,
            "rule_files": [str(GAME_RULES)], "board": BOARD,
            "config": {**cfg.to_dict(), "scenario_toml": scenario.to_toml(), "resumed_from": None}}
    writer = TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    trainer, status = None, "failed"
    t0 = time.perf_counter()
    try:
        trainer = Trainer(cfg, scenario, writer, run_dir, metric_sinks=metric_sinks)
        if started is not None:
            started(trainer)
        status = trainer.train()
        out = SeedRun(cfg.seed, run_dir, trainer.step, status, policy_dir=run_dir / "policy")
        policies = [("eval/", trainer.policy, out.final)]
        if trainer.best_eval is not None and trainer.best_eval[1] != trainer.step:  # else the final one
            out.best_step = trainer.best_eval[1]
            policies.append(("eval_best/", load_policy(run_dir / BEST_POLICY_DIR, scenario), out.best))
        for prefix, policy, into in policies:
            for p in eval_ps:  # the same games for both policies: a paired comparison
                result = evaluate(policy, scenario, games=eval_games, backend=cfg.backend,
                                  seed=final_eval_seed(cfg.seed, p), opponent_p=p, stack_previous=trainer.stack,
                                  envs=cfg.eval_envs)
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
