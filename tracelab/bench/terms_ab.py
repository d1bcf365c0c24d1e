"""The reward terms of a traced evaluation read by the compiled step against the per-step read they
replaced (issue 39), in one process: `python -m tracelab.bench.terms_ab [--blocks 12] [--evaluations 10]`.

Three traced evaluators of `tracelab bench eval`'s games (bench/eval.py: war.toml's 1v1 base game, 5 games
an evaluation, the same seeded untrained policy, the same seeds), each into its own run:
- `step`: as a traced evaluation records now: decisions, and the reward terms' quantities written by the
  compiled step (fused.read_step) and copied once a step (DeclaredWorld._reward_quantities),
- `read`: the same, the terms read as before (main up to 2026-11-29): after each step a Python read of
  the term atoms' bounds (a flat take, a compare with ones, a where for scaled atoms; `main_read`), the
  compiled step's own read off,
- `world`: no decisions, no reward terms (bench eval's `traced_world`).
Blocks of `evaluations` evaluations of each, the arms' order rotated every block; figures are the game
thread's CPU an evaluation (time.thread_time: it holds under load, where wall time does not), medians
of the blocks, and the medians of the blocks' ratios step / world, read / world and step / read. Both
term arms must record the same reward-term rows (`same_rows`).

An evaluation's difference between the two reads (~1 us a step, ~280 steps) is below what its blocks
resolve on a shared machine, so the world's step alone is timed too (`step_us`): three worlds of the same
game (terms kept by the step, read as before, not kept) stepping the same seeded random actions in
alternated blocks of `steps` steps, thread CPU µs a step (medians), and the medians of the blocks'
differences from the world that keeps none (`terms_us`). Prints one JSON object."""
from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path
from types import MethodType
from typing import Any

import numpy as np

from tracelab.bench import eval as bench_eval
from tracelab.bench.common import machine_info

ARMS = ("step", "read", "world")


def main_read(world: Any) -> None:
    """Make `world` read its reward terms as before issue 39's terms39: the compiled step's read off,
    each step's quantities read after it in Python (DeclaredWorld._reward_quantities as it was)."""
    reward_atoms, reward_is_table, keep_flag = world._term_reads
    keep_flag[0] = 0
    atoms = reward_atoms.reshape(world.n_agents, -1)
    is_table = reward_is_table.reshape(atoms.shape)[0].astype(bool) if atoms.size else np.zeros(0, bool)
    ones, all_table = np.ones(atoms.shape), bool(is_table.all())

    def read(self: Any) -> np.ndarray:
        bounds = self.engine.lower.ravel().take(atoms)  # a table atom is true where its lower bound is 1
        true = bounds == ones
        return true if all_table else np.where(is_table, true, bounds)
    world._reward_quantities = MethodType(read, world)


def _reward_rows(run: Path) -> list[tuple[Any, ...]]:
    """The run's reward-term rows (the rewards view), sorted."""
    from tracelab.store import open_run
    con = open_run(run)
    try:
        return sorted(con.execute("SELECT episode, step, agent, term, value, quantity FROM rewards").fetchall())
    finally:
        con.close()


def compare(blocks: int, evaluations: int) -> dict[str, Any]:
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.store import TraceWriter
    from tracelab.train.external_eval import DeclaredEvaluator, EvalSettings

    source = EnvSource(bench_eval.ENV_ID, {"p_toward": bench_eval.EVAL_P})
    policy = bench_eval._policy(source)
    settings = EvalSettings(games=5, traced=5, envs=5, level=bench_eval.EVAL_P)
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-terms-ab-") as tmp:
        arms: dict[str, tuple[Any, Any]] = {}
        for name in ARMS:
            writer = TraceWriter.open(Path(tmp) / name, {"command": "python -m tracelab.bench.terms_ab"})
            ids = iter(range(1 << 62))
            ev = DeclaredEvaluator(source, writer, lambda it=ids: next(it), settings, agent_rows=name != "world")
            arms[name] = (ev, writer)
        main_read(arms["read"][0].trace_env.unwrapped.world)
        cpu: dict[str, list[float]] = {k: [] for k in ARMS}
        round_no = 0
        for name in ARMS:  # warm-up: first calls, caches
            arms[name][0].play(policy if name != "world" else bench_eval._ActOnly(policy), 0, round_no)
        for block in range(blocks):
            order = ARMS[block % 3:] + ARMS[:block % 3]
            first = round_no + 1
            for name in order:
                ev, writer = arms[name]
                writer.flush()  # the last block's rows published: the writer's thread idle
                agent = policy if name != "world" else bench_eval._ActOnly(policy)
                t0 = time.thread_time()
                for r in range(first, first + evaluations):
                    ev.play(agent, 0, r)
                cpu[name].append((time.thread_time() - t0) / evaluations)
            round_no = first + evaluations - 1
        for ev, writer in arms.values():
            ev.close()
            writer.close()
        rows = _reward_rows(Path(tmp) / "step")
        same = rows == _reward_rows(Path(tmp) / "read")
    ratio = lambda a, b: statistics.median(x / y for x, y in zip(cpu[a], cpu[b]))  # noqa: E731
    return {"blocks": blocks, "evaluations_per_block": evaluations, "same_rows": same, "reward_rows": len(rows),
            "thread_ms": {k: round(1000 * statistics.median(v), 2) for k, v in cpu.items()},
            "step_over_world": round(ratio("step", "world"), 3), "read_over_world": round(ratio("read", "world"), 3),
            "step_over_read": round(ratio("step", "read"), 3)}


def step_costs(blocks: int, steps: int) -> dict[str, Any]:
    """Thread CPU µs a world step: terms kept by the step, read as before, and not kept (module docstring)."""
    from tracelab.envs.declared.env_source import EnvSource

    worlds = {}
    for name in ARMS:
        world = EnvSource(bench_eval.ENV_ID, {"p_toward": bench_eval.EVAL_P}).make().unwrapped.world
        world.keep_reward_terms = name != "world"
        if name == "read":
            main_read(world)
        worlds[name] = world
    us: dict[str, list[float]] = {k: [] for k in ARMS}
    for block in range(blocks + 1):  # the first block warms up
        for name in ARMS[block % 3:] + ARMS[:block % 3]:
            world, rng = worlds[name], np.random.default_rng(block)
            world.reset(rng)
            actions = rng.integers(world.n_actions, size=steps).tolist()
            t0 = time.thread_time()
            for a in actions:
                world.step(a, rng)
                if world.terminated():
                    world.reset(rng)
            if block:
                us[name].append((time.thread_time() - t0) / steps * 1e6)
    extra = lambda a: statistics.median(x - y for x, y in zip(us[a], us["world"]))  # noqa: E731
    return {"steps_per_block": steps, "step_us": {k: round(statistics.median(v), 2) for k, v in us.items()},
            "terms_us": {"step": round(extra("step"), 2), "read": round(extra("read"), 2)}}


def main() -> None:
    p = argparse.ArgumentParser(prog="python -m tracelab.bench.terms_ab", description=__doc__.split("\n")[0])
    p.add_argument("--blocks", type=int, default=12)
    p.add_argument("--evaluations", type=int, default=10)
    p.add_argument("--steps", type=int, default=2000, help="world steps a block of step_us")
    a = p.parse_args()
    load0 = machine_info()["load_average"]
    out = {**compare(a.blocks, a.evaluations), **step_costs(a.blocks, a.steps)}
    print(json.dumps({**out, "load_average": [load0, machine_info()["load_average"]]}))


if __name__ == "__main__":
    main()
