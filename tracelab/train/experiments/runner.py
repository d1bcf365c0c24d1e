"""Training and evaluating for the experiments, through the spec path (EnvTrainer on war.toml,
rules/gridworld/war*.toml, or on a world of its own): one run per seed, with the final policy evaluated
against each opponent setting and those figures written into the run's own `metrics` (suffix `@p0.3`,
`@p0.7`, docs/training.md), so `tracelab sql` sees them."""
from __future__ import annotations

import itertools
import shlex
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from tracelab.store import TraceWriter
from tracelab.store.queries import get_query
from tracelab.store.reader import fetch_arrow, open_run, query_readonly, retrying
from tracelab.train.config import TrainConfig
from tracelab.train.env_policy import BEST_POLICY_DIR
from tracelab.train.experiments.stats import spread, wilson
from tracelab.world_extras import evaluation_env

if TYPE_CHECKING:
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.envs.declared.gridwar_scenarios import ScenarioTraining
    from tracelab.train.env_policy import EnvEvalResult, EnvPolicy
    from tracelab.train.env_trainer import EnvTrainer
    from tracelab.train.tensorboard import MetricSink

WORLD_P = 0.0  # a world other than the war game has no opponent setting: its final evaluation's key
FINAL_EVAL_ROUND = 1_000_000  # seeds of the final evaluations: apart from the training's rounds
METHOD_CUT = 200  # the method's evaluation cut games at 200 steps: war.toml's step limit


@dataclass
class EvalFigures:
    """An evaluation's games as the reports read them (an env_policy.EnvEvalResult of a world that declares
    its outcomes, counted as the method counts: a game cut at the world's step limit a loss, draws non-wins).
    Its fields but the per-game lists are those of the reports' JSON (load_result reads them back)."""
    games: int = 0
    wins: int = 0
    losses: int = 0
    draws: int = 0
    truncated: int = 0
    mean_return: float = 0.0
    actions_per_win: float | None = None
    method_wins: int = 0
    method_losses: int = 0       # losses, plus games cut at the step limit
    method_non_wins: int = 0     # draws
    method_actions_per_win: float | None = None
    # per game, in the order the games ended (not in the JSON): portability compares two evaluations by them
    returns: list[float] = field(default_factory=list, repr=False)
    lengths: list[int] = field(default_factory=list, repr=False)

    @classmethod
    def of(cls, r: EnvEvalResult) -> "EvalFigures":
        wins = r.wins or 0  # none declared: no wins
        apw = float(np.mean(r.win_steps)) if r.win_steps else None
        return cls(games=r.games, wins=wins, losses=r.losses, draws=r.draws, truncated=r.truncated,
                   mean_return=r.mean_return, actions_per_win=apw, method_wins=wins,
                   method_losses=r.losses + r.truncated, method_non_wins=r.draws, method_actions_per_win=apw,
                   returns=list(r.returns), lengths=list(r.steps))

    @property
    def win_rate(self) -> float:
        return self.wins / self.games if self.games else 0.0

    @property
    def method_win_rate(self) -> float:
        return self.method_wins / self.games if self.games else 0.0

    def to_dict(self) -> dict[str, Any]:
        """The JSON of a report: the counts, both win rates and their 95% intervals (Wilson; a t-interval of
        the mean return with two games or more)."""
        d = {k: v for k, v in asdict(self).items() if k not in ("returns", "lengths")}
        d.update(win_rate=self.win_rate, method_win_rate=self.method_win_rate,
                 win_rate_ci95=list(wilson(self.wins, self.games)),
                 method_win_rate_ci95=list(wilson(self.method_wins, self.games)))
        if len(self.returns) > 1:
            s = spread(self.returns)
            d["mean_return_ci95"] = [s["ci_low"], s["ci_high"]]
        return d

    def metrics(self, suffix: str = "", prefix: str = "eval/") -> dict[str, float]:
        """The run's `eval/...` metric rows (docs/training.md); `eval_best/` for the kept best policy."""
        m = {"games": self.games, "wins": self.wins, "losses": self.losses, "draws": self.draws,
             "truncated": self.truncated, "win_rate": self.win_rate, "mean_return": self.mean_return,
             "method_win_rate": self.method_win_rate}
        if self.actions_per_win is not None:
            m["actions_per_win"] = self.actions_per_win
        return {f"{prefix}{k}{suffix}": float(v) for k, v in m.items()}


@dataclass
class SeedRun:
    """One trained seed: its run, its final evaluations per opponent p, its policy."""
    seed: int
    run_dir: Path
    steps: int
    status: str
    final: dict[float, EvalFigures] = field(default_factory=dict)
    policy_dir: Path | None = None
    best: dict[float, EvalFigures] = field(default_factory=dict)  # the kept best policy's (RUN/policy-best)
    best_step: int | None = None                                 # the step it was saved at
    wall_s: float = 0.0


CLOSE_WAIT_S = 60  # how long a stopped or cancelled training may take to close its run


def p_suffix(p: float) -> str:
    return f"@p{p:g}"


def final_eval_seed(seed: int, p: float) -> int:
    return int(np.random.SeedSequence([seed, 3, FINAL_EVAL_ROUND, int(round(p * 1000))]).generate_state(1)[0])


def train_seed(cfg: TrainConfig, world: ScenarioTraining | EnvSource, run_dir: Path, command: str,
               eval_ps: tuple[float, ...], eval_games: int, metric_sinks: Sequence[MetricSink] = (),
               started: Callable[[EnvTrainer], None] | None = None) -> SeedRun:
    """Train `cfg` into a new run at `run_dir`, then evaluate the final policy `eval_games` games
    against each opponent p in `eval_ps`, writing `eval/...@pP` metrics at the last step. `metric_sinks`
    receive the training's metrics besides the run; `started` is called with the trainer before it trains
    (a sweep's trial stops it through it: stop_requested). `world`: an env, or the war game's scenario
    (_parts)."""
    # deferred: torch and the trainers, which reading results and queries does not need
    import torch

    meta, make_trainer, final_evaluation = _parts(cfg, world, command, eval_ps, eval_games)
    writer = TraceWriter.open(run_dir, meta)
    torch.set_num_threads(cfg.threads)
    trainer, status = None, "failed"
    t0 = time.perf_counter()
    try:
        trainer = make_trainer(cfg, world, writer, run_dir, metric_sinks=metric_sinks)
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


FinalEvaluation = Callable[[Any, Any], dict[float, EvalFigures]]  # (trainer, policy or its folder) -> per p


def _parts(cfg: TrainConfig, world: ScenarioTraining | EnvSource, command: str, eval_ps: tuple[float, ...],
           eval_games: int) -> tuple[dict[str, Any], Any, FinalEvaluation]:
    """The run meta, the trainer and the final evaluation of `world`: an env, as `train --env` trains it, or
    the war game's scenario training, as `train --scenario` does (the run names the scenario, its
    evaluations play its eval_source). The final evaluation: `eval_games` games at each level of `eval_ps`
    (the env world_extras.evaluation_env gives there, else the world's own: one level, WORLD_P), counted as
    the world declares ([end] win / loss)."""
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.train.env_policy import evaluate_env, load_env_policy
    from tracelab.train.env_trainer import EnvTrainer, env_run_meta

    if isinstance(world, EnvSource):
        source, eval_source = world, None
        meta = env_run_meta(cfg, source, f"tracelab train --env (from: {command})")
    else:
        source, eval_source = world.source, world.eval_source
        meta = env_run_meta(cfg, source, f"tracelab train (from: {command})", None, world)

    def make_trainer(cfg: TrainConfig, _: Any, *args: Any, **kw: Any) -> EnvTrainer:
        return EnvTrainer(cfg, source, *args, eval_source=eval_source, **kw)

    def final_evaluation(trainer: Any, policy: Any) -> dict[float, EvalFigures]:
        if isinstance(policy, Path):
            policy = load_env_policy(policy, source)[0]
        return {p: EvalFigures.of(evaluate_env(policy, evaluation_env(source, p) or source, eval_games,
                                               final_eval_seed(cfg.seed, p), cfg.eval_envs))
                for p in eval_ps}
    return meta, make_trainer, final_evaluation


def traced_games(policy: EnvPolicy, source: EnvSource, run_dir: Path, *, games: int, seed: int, command: str,
                 about: dict[str, Any], level: float | None = None) -> EvalFigures:
    """`games` greedy games of `policy` on the declared world `source` (at the evaluation `level`, if given, as
    the final evaluation's), every one traced in full into a new run (as a training's traced evaluation games are,
    external_eval.DeclaredEvaluator): the saved queries then read only these games. Game k is seeded from
    `seed` (eval_seed(seed, 0) + 1 + k)."""
    from tracelab.envs.declared.play import load_declared
    from tracelab.train.external_eval import DeclaredEvaluator, DeclaredTarget, EvalSettings

    source = source if level is None else evaluation_env(source, level) or source
    described = DeclaredTarget(source, load_declared(source)).run_meta()
    meta = {"command": command, "seed": seed, **described,
            "config": {**about, "games": games, **described["config"]}}
    writer = TraceWriter.open(run_dir, meta)
    status = "failed"
    evaluator = DeclaredEvaluator(source, writer, itertools.count().__next__,
                                  EvalSettings(every=0, games=games, traced=games, envs=1, seed=seed))
    try:
        result = EvalFigures.of(evaluator.play(policy, 0, 0))
        writer.write_metrics(0, result.metrics(p_suffix(WORLD_P if level is None else level)))
        status = "finished"
        return result
    finally:
        evaluator.close()
        writer.close(status=status)


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
