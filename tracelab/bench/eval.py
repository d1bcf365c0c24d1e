"""`tracelab bench eval`: what tracing costs `tracelab train`'s evaluations, and the memory of a long
training with traced evaluations.

Speed, in one process: the same evaluation games of war.toml's 1v1 base game (gridwar.BASE_ID, against
the opponent at train's --eval-p; one policy: a seeded untrained network; the same seeds) played
- `traced`: as train traces them (external_eval.DeclaredEvaluator: `worlds` games one at a time in a traced
  env, into a run of the store that stays open, as the training's run does), the policy's decisions and
  the reward terms recorded,
- `untraced`: as train plays the rest (env_policy.play_env_games in a vector env of `worlds` worlds, no
  trace),
- `traced_world`: traced as before issue 39, the world's half only: no decisions, no reward terms (a
  recorder without the agent's rows, into a second run),
in turn, `evaluations` evaluations per block, `repeats` blocks of each; a traced block ends when the run's
writer has published its rows (its thread would otherwise encode them during the next untraced block,
whose process CPU time would count them). Figures are seconds per evaluation,
medians: wall clock, CPU of the whole process (the store writer's thread included) and CPU of the game's
thread alone. `ratio`: traced over untraced per CPU second and per wall second (the goal: <= 1.3);
`agent_ratio`: traced over traced_world (issue 39's goal: <= 1.1). All must play the same games
(`same_games`: their returns and lengths compared).

Memory (`--memory STEPS`): `tracelab train --scenario base --total-timesteps STEPS --eval-every 10000
--eval-games 50 --trace-eval-games 5` in a fresh process, its resident memory sampled every second
(common.sampled_child_rss) and its peak. Flat after warm-up: the growth from the median of the samples in
the second tenth of the run to the median of those in its last tenth."""
from __future__ import annotations

import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.bench.common import format_table, machine_info, sampled_child_rss, summarize
from tracelab.bench.engine import machine_line
from tracelab.envs.declared.gridwar import BASE_ID

GOAL_RATIO = 1.3
AGENT_GOAL_RATIO = 1.1  # issue 39: recording the agent's half costs traced evaluations at most 10%
SCENARIO = "base"
ENV_ID = BASE_ID  # the base scenario's spec
EVAL_P = 0.3   # train's --eval-p
MEMORY_TRAIN_ARGS = ("--scenario", SCENARIO, "--eval-every", "10000", "--eval-games", "50",
                     "--trace-eval-games", "5")


class _ActOnly:
    """A policy that only acts: a traced env records no decisions of it."""

    def __init__(self, policy: Any) -> None:
        self.act = policy.act


def _policy(source: Any) -> Any:
    """A seeded, untrained greedy policy of the 1v1 base game (the network shape train starts from, its
    weights drawn as torch's default initialisation draws them: uniform in +-1/sqrt(fan-in))."""
    from tracelab.train.config import TrainConfig
    from tracelab.train.env_policy import EnvPolicy
    from tracelab.train.env_source import probe_env
    from tracelab.train.qnet import NumpyQ
    encoder, n_actions, _ = probe_env(source)
    net = TrainConfig().network(encoder.size, n_actions)
    rng = np.random.default_rng(0)
    weights = {}
    for key, shape in net.state_dict_shapes().items():
        fan_in = shape[-1] if len(shape) > 1 else shape[0]
        weights[key] = rng.uniform(-1, 1, shape).astype(np.float32) / np.sqrt(fan_in)
    return EnvPolicy(NumpyQ(net, weights), encoder)


Evaluation = Callable[[int], list[tuple[float, int]]]  # evaluation round -> the games' (return, steps)


def evaluations(worlds: int, run_dir: Path) -> tuple[Evaluation, Evaluation, Evaluation,
                                                     Callable[[], tuple[int, int]], Callable[[], None]]:
    """(traced, untraced, traced_world, published, close): an evaluation round of `worlds` games, traced
    into a new run at `run_dir`, untraced, or traced without the agent's decisions and reward terms into
    `run_dir`-world; `published()` returns once the traced rows are in the runs, with the two runs'
    publications so far (traced, traced_world)."""
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.store import TraceWriter
    from tracelab.train.env_policy import make_vector_env, play_env_games
    from tracelab.train.external_eval import DeclaredEvaluator, EvalSettings
    from tracelab.train.rngs import eval_seed

    source = EnvSource(ENV_ID, {"p_toward": EVAL_P})
    policy = _policy(source)
    settings = EvalSettings(games=worlds, traced=worlds, envs=worlds, level=EVAL_P)
    writer = TraceWriter.open(run_dir, {"command": "tracelab bench eval", "scenario": SCENARIO})
    ids = iter(range(1 << 62))
    trace = DeclaredEvaluator(source, writer, lambda: next(ids), settings)
    world_writer = TraceWriter.open(run_dir.with_name(run_dir.name + "-world"), {"command": "tracelab bench eval"})
    world_ids = iter(range(1 << 62))
    world_trace = DeclaredEvaluator(source, world_writer, lambda: next(world_ids), settings, agent_rows=False)
    env, _ = make_vector_env(source, worlds)

    def games(result: Any) -> list[tuple[float, int]]:
        return list(zip(result.returns, result.steps))

    def published() -> tuple[int, int]:
        writer.flush()
        world_writer.flush()
        return writer.flushes, world_writer.flushes

    def close() -> None:
        trace.close()
        world_trace.close()
        env.close()
        writer.close()
        world_writer.close()

    # the traced games of round r are seeded eval_seed + 1 + k, as world k of a vector env reset with eval_seed + 1
    return (lambda r: games(trace.play(policy, 0, r)),
            lambda r: games(play_env_games(env, policy, worlds, eval_seed(settings.seed, r) + 1)),
            lambda r: games(world_trace.play(_ActOnly(policy), 0, r)), published, close)


def speed(worlds: int, per_block: int, repeats: int) -> dict[str, Any]:
    """Traced and untraced evaluations of `worlds` games, in turn (module docstring)."""
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-eval-") as tmp:
        traced, untraced, traced_world, published, close = evaluations(worlds, Path(tmp) / "run")
        try:
            same = sorted(traced(0)) == sorted(untraced(0)) == sorted(traced_world(0))  # untraced: in order of ending
            published()
            kinds = {"traced": traced, "untraced": untraced, "traced_world": traced_world}
            figures: dict[str, dict[str, list[float]]] = {k: {"wall": [], "cpu": [], "thread": []} for k in kinds}
            steps = {k: 0 for k in kinds}
            publications = {"traced": 0, "traced_world": 0}
            for block in range(max(1, repeats)):
                rounds = range(1 + block * per_block, 1 + (block + 1) * per_block)
                for name, play in kinds.items():
                    before = published() if name.startswith("traced") else (0, 0)
                    t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
                    for round_no in rounds:
                        steps[name] += sum(n for _, n in play(round_no))
                    if name.startswith("traced"):
                        publications[name] += published()[name == "traced_world"] - before[name == "traced_world"]
                    for key, used in (("wall", time.perf_counter() - t0), ("cpu", time.process_time() - c0),
                                      ("thread", time.thread_time() - m0)):
                        figures[name][key].append(used / per_block)
        finally:
            close()
    out: dict[str, Any] = {"worlds": worlds, "evaluations_per_block": per_block, "same_games": same,
                           "game_steps": steps,
                           "publications_per_evaluation": {k: n / (per_block * max(1, repeats))
                                                           for k, n in publications.items()}}
    for name, f in figures.items():
        out[name] = {f"{key}_s": summarize(v).to_dict() for key, v in f.items()}
    for key in ("wall", "cpu", "thread"):  # medians of the blocks' ratios: each pair shares the load
        out[f"ratio_{key}"] = statistics.median(t / u for t, u in zip(figures["traced"][key],
                                                                        figures["untraced"][key]))
        out[f"agent_ratio_{key}"] = statistics.median(t / u for t, u in zip(figures["traced"][key],
                                                                              figures["traced_world"][key]))
    out["goal_met"] = out["ratio_cpu"] <= GOAL_RATIO
    out["agent_goal_met"] = out["agent_ratio_cpu"] <= AGENT_GOAL_RATIO
    return out


def memory(steps: int) -> dict[str, Any]:
    """A `tracelab train` of `steps` steps with traced evaluations in a fresh process, its RSS sampled."""
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-eval-memory-") as tmp:
        argv = [sys.executable, "-m", "tracelab", "train", *MEMORY_TRAIN_ARGS, "--total-timesteps", str(steps),
                "--run", str(Path(tmp) / "run")]
        r = sampled_child_rss(argv, every_s=1.0)
    if r["returncode"] != 0:
        raise RuntimeError(f"the training failed ({r['returncode']}): {r['stderr']}")
    return {"steps": steps, "command": " ".join(["tracelab", *argv[3:-2]]), **flatness(r["rss_mb"]),
            "peak_mb": r["peak_mb"], "seconds": r["seconds"], "rss_mb": r["rss_mb"]}


def flatness(samples: list[tuple[float, float]]) -> dict[str, float]:
    """RSS after warm-up (median of the second tenth of the samples), at the end (median of the last
    tenth) and the growth between them, MB."""
    mb = [m for _, m in samples]
    tenth = max(1, len(mb) // 10)
    after_warm_up = statistics.median(mb[tenth:2 * tenth] or mb)
    end = statistics.median(mb[-tenth:])
    return {"after_warm_up_mb": after_warm_up, "end_mb": end, "growth_mb": end - after_warm_up}


def run(quick: bool = False, repeats: int = 5, worlds: int = 5, memory_steps: int | None = None) -> dict[str, Any]:
    info = machine_info()
    result = speed(worlds, 2 if quick else 20, repeats)
    mem = memory(memory_steps) if memory_steps else None
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "scenario": SCENARIO, "speed": result,
            "memory": mem}


def report(r: dict[str, Any]) -> str:
    s = r["speed"]
    ms = lambda d: 1000 * d["median"]  # noqa: E731
    rows = [[name, ms(s[name]["wall_s"]), ms(s[name]["cpu_s"]), ms(s[name]["thread_s"]),
             f"{100 * s[name]['cpu_s']['spread']:.0f}%"] for name in ("traced", "traced_world", "untraced")]
    rows.append(["traced / untraced", s["ratio_wall"], s["ratio_cpu"], s["ratio_thread"], ""])
    rows.append(["traced / traced_world", s["agent_ratio_wall"], s["agent_ratio_cpu"], s["agent_ratio_thread"], ""])
    parts = [machine_line(r["machine"], r["quick"], r["repeats"]),
             f"an evaluation of {s['worlds']} games of {r['scenario']} (one per world, a seeded untrained policy, "
             f"the same seeds), ms each, {s['evaluations_per_block']} per block; the same games: "
             f"{'yes' if s['same_games'] else 'NO'}\n"
             + format_table(["evaluation", "wall", "CPU (process)", "CPU (game's thread)", "CPU spread"], rows)
             + "\nthe writer's publications per evaluation (the block's last flush included): "
             + ", ".join(f"{k} {v:.2f}" for k, v in s.get("publications_per_evaluation", {}).items()),
             f"goal traced <= {GOAL_RATIO}x untraced per CPU second: "
             f"{'met' if s['goal_met'] else 'not met'} ({s['ratio_cpu']:.2f}x)",
             f"goal decisions and reward terms <= {AGENT_GOAL_RATIO}x the world's trace alone (traced_world) per "
             f"CPU second: {'met' if s['agent_goal_met'] else 'not met'} ({s['agent_ratio_cpu']:.2f}x)"]
    m = r["memory"]
    if m:
        parts.append(f"{m['command']}, a fresh process, RSS every second: "
                     f"{m['after_warm_up_mb']:.0f} MB after warm-up (second tenth), {m['end_mb']:.0f} MB in the "
                     f"last tenth ({m['growth_mb']:+.0f} MB), peak {m['peak_mb']:.0f} MB, {m['seconds']:.0f} s")
    return "\n\n".join(parts)
