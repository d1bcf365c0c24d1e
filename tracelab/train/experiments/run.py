"""Running one experiment: train every arm once per seed (tracelab/train/experiments/runner.py), the
experiment's own measurements (portability, reward shaping), then the report and its plots."""
from __future__ import annotations

import json
import multiprocessing
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from tracelab.provenance import machine_summary, source_commit
from tracelab.train.config import TrainConfig
from tracelab.train.experiments.definitions import Arm, Budget, Experiment
from tracelab.train.experiments.runner import (
    CLOSE_WAIT_S,
    WORLD_P,
    EvalFigures,
    SeedRun,
    final_eval_seed,
    p_suffix,
    run_query,
    run_sql,
    traced_games,
    train_seed,
)
from tracelab.train.experiments.stats import bootstrap_diff_ci, two_proportion_test
from tracelab.train.env_policy import load_env_policy

if TYPE_CHECKING:
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.envs.declared.gridwar_scenarios import ScenarioTraining

RESULT_POLL_S = 0.2  # how often the experiment looks for a worker's finished training
TRAIN_P, EVAL_PS = 0.7, (0.3, 0.7)  # the method's code: trained against p = 0.7, evaluated against 0.3

Say = Callable[[str], None]


@dataclass
class ArmResult:
    arm: Arm
    seeds: list[SeedRun] = field(default_factory=list)
    extra: dict[int, dict[str, Any]] = field(default_factory=dict)  # seed -> experiment-specific figures


@dataclass
class ExperimentResult:
    experiment: Experiment
    budget: Budget
    quick: bool
    out_dir: Path
    arms: list[ArmResult]
    wall_s: float = 0.0
    command: str = ""
    commit: str = ""   # the code that trained (git HEAD when the experiment started)
    machine: str = ""  # cores, CPU, the load when it ended


def commit() -> str:
    """The code that trains: git HEAD (with its uncommitted-changes note) when the experiment starts."""
    return source_commit() or "unknown (not a git checkout)"


def machine() -> str:
    """Called when the experiment ends: the load average is the one at its end."""
    return machine_summary("at the end")


def train_config(exp: Experiment, arm: Arm, budget: Budget, seed: int) -> TrainConfig:
    evals = max(1, budget.evals)
    common = dict(steps=budget.steps, seed=seed, eval_games=budget.eval_games,
                  eval_every=budget.steps // evals if evals > 1 else 0,
                  trace_eval_games=min(5, budget.eval_games), eval_envs=min(50, budget.eval_games),
                  checkpoint_every=0, log_every=min(1_000, max(100, budget.steps // 20)),
                  warmup=min(1_000, budget.steps // 4), **{**exp.train, **arm.train})
    return TrainConfig(**common)


def arm_world(arm: Arm) -> ScenarioTraining | EnvSource:
    """What an arm trains on: a world arm's env, or the war game's scenario against the opponent at TRAIN_P,
    evaluated during training at EVAL_PS[0]."""
    if arm.env is not None:
        return arm.build_world()
    from tracelab.envs.declared.gridwar_scenarios import ScenarioTraining  # deferred: gymnasium, the engine
    return ScenarioTraining.of(arm.build_scenario(), TRAIN_P, EVAL_PS[0], arm.non_markov)


def trainer_note(exp: Experiment) -> str:
    """Which trainer the experiment's arms go through, as its log and report say it: every one trains
    through a spec (issue 38: RuleSim's Trainer is no longer used)."""
    if is_world(exp):
        return "trains through the world's spec (EnvTrainer)"
    return "trains the war game through its spec (rules/gridworld/war*.toml, EnvTrainer)"


def eval_ps(exp: Experiment) -> tuple[float, ...]:
    """The opponent settings the final policies are evaluated against: the war game's two, or a world's one
    evaluation (WORLD_P: it has no opponent)."""
    return (WORLD_P,) if is_world(exp) else EVAL_PS


def is_world(exp: Experiment) -> bool:
    """An experiment on a world other than the war game (its arms name an env)."""
    return any(a.env is not None for a in exp.arms)


def run_experiment(exp: Experiment, budget: Budget, out_dir: Path, command: str, quick: bool,
                   say: Say = print, jobs: int = 1, kernel: str = "auto",
                   ray: str | None = None) -> ExperimentResult:
    """Train every arm once per seed (`jobs` trainings at a time, each in its own process; or, with `ray`
    a Ray address or "local", each as a Ray task), then the experiment's own measurements on the saved
    policies. `kernel`: the trainings' (TrainConfig.kernel; the results do not depend on it)."""
    t0 = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    result = ExperimentResult(exp, budget, quick, out_dir, [ArmResult(a) for a in exp.arms], command=command,
                              commit=commit())
    tasks = [(ar, seed) for ar in result.arms for seed in range(budget.seeds)]

    def task_args(ar: ArmResult, seed: int) -> tuple:
        cfg = train_config(exp, ar.arm, budget, seed)
        return (cfg if is_world(exp) else replace(cfg, kernel=kernel), arm_world(ar.arm),
                out_dir / f"{ar.arm.slug}-seed{seed}", command, eval_ps(exp), budget.eval_games)

    say(f"[{exp.name}] {trainer_note(exp)}")

    for ar, seed in tasks:
        say(f"[{exp.name}] {ar.arm.label}, seed {seed}: training {budget.steps:,} steps into "
            f"{out_dir / f'{ar.arm.slug}-seed{seed}'}")
    if ray is not None and is_world(exp):
        raise ValueError(f"{exp.name}: --ray runs the war game's experiments only for now; use --jobs")
    if ray is not None:
        # deferred: Ray is an optional extra (tracelab[ray])
        from tracelab.train.experiments.ray_tasks import in_ray_tasks
        runs = in_ray_tasks([task_args(ar, seed) for ar, seed in tasks], ray)
    elif jobs > 1 and len(tasks) > 1:
        runs = _in_workers(min(jobs, len(tasks)), [task_args(ar, seed) for ar, seed in tasks])
    else:
        runs = [train_seed(*task_args(ar, seed)) for ar, seed in tasks]
    for (ar, seed), sr in zip(tasks, runs):
        ar.seeds.append(sr)
        say(f"[{exp.name}] {ar.arm.label}, seed {seed}: {sr.status} after {sr.wall_s:.0f} s; "
            + ", ".join(f"method's win rate{'' if is_world(exp) else f' vs p={p:g}'}: "
                        f"{100 * r.method_win_rate:.1f}%" for p, r in sr.final.items()))
        if exp.name == "portability":
            ar.extra[seed] = portability(sr, ar.arm, train_config(exp, ar.arm, budget, seed),
                                         budget.eval_games, say)
        elif exp.name == "reward-shaping":
            ar.extra[seed] = shaping_traces(sr, arm_world(ar.arm).source, out_dir, 6 if quick else 100, command,
                                            say)
    result.wall_s = time.perf_counter() - t0
    result.machine = machine()
    (out_dir / f"{exp.name}.json").write_text(json.dumps(summary_json(result), indent=1))
    return result


def _in_workers(jobs: int, args: list[tuple]) -> list[SeedRun]:
    """train_seed on each of `args` in `jobs` spawned processes. Any way out before all are done (Ctrl-C,
    SIGTERM, a failed training) terminates the workers: a killed experiment leaves no orphans training on
    (each worker's SIGTERM closes its run as 'interrupted', docs/store.md)."""
    pool = multiprocessing.get_context("spawn").Pool(jobs)
    try:
        pending = [pool.apply_async(train_seed, a) for a in args]
        runs = []
        for result in pending:
            # sleep, not result.get(): the interrupt lands here, never inside the result's Event, whose
            # lock it could leave held (threading's Condition takes it in Python code), and then the
            # pool's result thread, and terminate(), would wait for it forever
            while not result.ready():
                time.sleep(RESULT_POLL_S)
            runs.append(result.get())
    except BaseException:
        _terminate(pool)
        raise
    pool.close()
    pool.join()
    return runs


def _terminate(pool: Any) -> None:
    """pool.terminate(), bounded: it sends each worker SIGTERM and waits for it, and a worker that does
    not end (its SystemExit raised where something swallowed it, a close that hung) would keep it waiting
    forever; after CLOSE_WAIT_S the workers still alive are killed (their runs then read as crashed)."""
    stopper = threading.Thread(target=pool.terminate, name="pool-terminate", daemon=True)
    stopper.start()
    stopper.join(CLOSE_WAIT_S)
    if stopper.is_alive():
        for worker in multiprocessing.active_children():
            worker.kill()
        stopper.join(CLOSE_WAIT_S)


# ---- portability: the same policy in both simulators ----
def portability(sr: SeedRun, arm: Arm, cfg: TrainConfig, games: int, say: Say) -> dict[str, Any]:
    """Per opponent p: the spec policy's games in the reference simulator (RefSim) with the spec world's
    final-evaluation seeds (game by game identical if the simulators agree) and with other seeds (an
    independent sample: the gap and a test of it)."""
    # deferred: RefSim's numba kernels, which a report written again does not need
    from tracelab.train.experiments.refsim_games import refsim_games

    policy = load_env_policy(sr.policy_dir, arm_world(arm).source)[0]
    scenario = arm.build_scenario()
    out: dict[str, Any] = {}
    for p in EVAL_PS:
        rules = sr.final[p]
        same, other = (EvalFigures.of(refsim_games(policy, scenario, games, final_eval_seed(sr.seed, p) + k,
                                                   cfg.eval_envs, p, arm.non_markov)) for k in (0, 1))
        identical = sum(a == b for a, b in zip(zip(rules.returns, rules.lengths), zip(same.returns, same.lengths)))
        z, pval = two_proportion_test(rules.method_wins, rules.games, other.method_wins, other.games)
        lo, hi = bootstrap_diff_ci(rules.returns, other.returns)
        rel = (abs(rules.mean_return - other.mean_return) / abs(other.mean_return)
               if other.mean_return else float("nan"))
        out[p_suffix(p)] = {
            "rules": rules.to_dict(), "reference_same_seeds": same.to_dict(), "reference_other_seeds": other.to_dict(),
            "identical_games": identical, "games": games,
            "win_gap_points": 100 * (rules.method_win_rate - other.method_win_rate), "z": z, "p_value": pval,
            "return_gap": rules.mean_return - other.mean_return, "return_gap_ci": [lo, hi],
            "return_gap_relative": rel}
        say(f"  p={p:g}: {identical}/{games} games identical with the same seeds; other seeds: "
            f"{100 * rules.method_win_rate:.1f}% vs {100 * other.method_win_rate:.1f}% (p-value {pval:.2f})")
    return out


# ---- reward shaping: the saved queries on traced evaluation games ----
def shaping_traces(sr: SeedRun, source: EnvSource, out_dir: Path, games: int, command: str, say: Say) -> dict[str, Any]:
    """Trace `games` evaluation games of the final policy (against p = 0.3) in its spec world (`source`,
    the arm's spec id and params) into their own run and read the saved queries' figures off it."""
    policy = load_env_policy(sr.policy_dir, source)[0]
    trace_dir = out_dir / f"{sr.run_dir.name}-traces"
    traced_games(policy, source, trace_dir, games=games, seed=final_eval_seed(sr.seed, EVAL_PS[0]) + 2,
                 command=f"tracelab eval (from: {command})", about={"policy": str(sr.policy_dir)}, level=EVAL_PS[0])
    figures = query_figures(trace_dir, action_names(source))
    figures["trace_run"] = str(trace_dir)
    say(f"  traced {games} games into {trace_dir}: " + ", ".join(
        f"{k} {v:.2f}" for k, v in figures.items() if isinstance(v, float)))
    return figures


def action_names(source: EnvSource) -> list[str]:
    """The spec's action names, by action id (what the traces' steps.action holds)."""
    from tracelab.envs.declared.play import load_declared
    return list(load_declared(source).action_names)


def query_figures(run: Path, actions: list[str]) -> dict[str, Any]:
    """Per-game figures of the four saved queries on a run of traced evaluation games of a world whose
    action ids name `actions`."""
    hid = run_query(run, "hid_behind_mountain")
    ev = run_query(run, "learner_events")
    apw = run_query(run, "actions_per_win", learner="red-agent-%")
    before_loss = run_query(run, "steps_before_loss", learner="red-agent-%")
    games = max(1, len(ev))
    shoot_ids = ", ".join(str(i) for i, name in enumerate(actions) if name.startswith("shoot")) or "NULL"
    shots = run_sql(run, f"SELECT count(*) FILTER (action IN ({shoot_ids})) AS shots, count(*) AS actions "
                         "FROM steps WHERE agent LIKE 'red-agent-%'")[0]
    last_actions: dict[str, int] = {}
    for r in before_loss:  # steps.action is the spec's action id
        name = actions[r["action"]] if 0 <= r["action"] < len(actions) else str(r["action"])
        last_actions[name] = last_actions.get(name, 0) + 1
    return {
        "games": len(ev),
        "hidden_steps_per_game": float(np.mean([r["hidden_steps"] for r in hid])) if hid else 0.0,
        "games_with_hiding": float(sum(r["hidden_steps"] > 0 for r in hid) / games),
        "shot_per_game": float(sum(r["shot"] for r in ev) / games),
        "unsafe_per_game": float(sum(r["unsafe"] for r in ev) / games),
        "invalid_per_game": float(sum(r["invalid"] for r in ev) / games),
        "shoot_share": float(shots["shots"] / shots["actions"]) if shots["actions"] else 0.0,
        "wins": int(apw[0]["wins"]) if apw else 0,
        "actions_per_win": float(apw[0]["actions_per_win"]) if apw and apw[0]["traced_wins"] else float("nan"),
        "losses": len({r["episode"] for r in before_loss}),
        "actions_before_loss": dict(sorted(last_actions.items(), key=lambda kv: -kv[1])),
    }


def summary_json(result: ExperimentResult) -> dict[str, Any]:
    return {"experiment": result.experiment.name, "command": result.command, "commit": result.commit,
            "machine": result.machine,
            "quick": result.quick,
            "budget": vars(result.budget), "wall_s": result.wall_s,
            "arms": [{"label": ar.arm.label, "published": ar.arm.published,
                      "seeds": [{"seed": s.seed, "run": str(s.run_dir), "steps": s.steps, "status": s.status,
                                 "wall_s": s.wall_s,
                                 "final": {p_suffix(p): r.to_dict() for p, r in s.final.items()},
                                 "best_step": s.best_step,
                                 "best": {p_suffix(p): r.to_dict() for p, r in s.best.items()},
                                 "extra": ar.extra.get(s.seed)} for s in ar.seeds]}
                     for ar in result.arms]}


def load_result(exp: Experiment, out_dir: Path) -> ExperimentResult:
    """An experiment's result as run_experiment left it in `out_dir` (its NAME.json), to write the report
    again without training."""
    path = out_dir / f"{exp.name}.json"
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: no result of a finished experiment here ({e})") from None
    fields_ = set(EvalFigures.__dataclass_fields__) - {"returns", "lengths"}
    result = ExperimentResult(exp, Budget(**d["budget"]), d["quick"], out_dir, [ArmResult(a) for a in exp.arms],
                              wall_s=d["wall_s"], command=d.get("command", ""), commit=d.get("commit", ""),
                              machine=d.get("machine", ""))
    def evals(saved: dict[str, Any]) -> dict[float, EvalFigures]:
        return {float(k[2:]): EvalFigures(**{f: v for f, v in r.items() if f in fields_}) for k, r in saved.items()}

    for ar, saved in zip(result.arms, d["arms"]):
        for s in saved["seeds"]:
            run_dir = Path(s["run"])
            ar.seeds.append(SeedRun(s["seed"], run_dir, s["steps"], s["status"], evals(s["final"]),
                                    run_dir / "policy", evals(s.get("best", {})), s.get("best_step"),
                                    s.get("wall_s", 0.0)))
            if s.get("extra") is not None:
                ar.extra[s["seed"]] = s["extra"]
    if not result.command:  # written before the command was kept: the runs' meta holds it
        meta = json.loads((result.arms[0].seeds[0].run_dir / "meta.json").read_text())
        result.command = meta["command"].removeprefix("tracelab train (from: ").removesuffix(")")
    return result


def scaled(budget: Budget, seeds: int | None, steps: int | None, eval_games: int | None) -> Budget:
    return replace(budget, **{k: v for k, v in (("seeds", seeds), ("steps", steps), ("eval_games", eval_games))
                              if v is not None})


__all__ = ["run_experiment", "scaled", "ExperimentResult", "EvalFigures"]
