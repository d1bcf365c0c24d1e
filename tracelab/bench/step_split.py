"""Where a batch's step goes on the war game's spec (bench env's workload, tracelab.bench.sims.SpecLoop): CPU seconds
inside the lanes kernel's step (lanes.step_lanes), its restores (restore_worlds, restore_worlds_from) and the
rest, with the engine's work counters per world-step:
`python -m tracelab.bench.step_split --agents 20 --worlds 256 [--steps 40] [--trace]`.
Prints one JSON line per (agents, worlds)."""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any


from tracelab.engine import lanes as L
from tracelab.engine.core import STAT_NAMES
from tracelab.bench.sims import SpecLoop, team_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds

TIMED = ("step_lanes", "restore_worlds", "restore_worlds_from")


def _timed(fn: Callable[..., Any], spent: dict[str, float], name: str) -> Callable[..., Any]:
    def call(*args: Any) -> Any:
        c0 = time.thread_time()
        try:
            return fn(*args)
        finally:
            spent[name] += time.thread_time() - c0
    return call


def split(agents: int, worlds: int, steps: int, trace: bool) -> dict[str, Any]:
    batch = DeclaredWorlds(team_spec(agents), worlds)
    loop = SpecLoop(batch, trace)
    loop.run(max(2, steps // 4))  # warm-up: first calls, the grounding table's growth
    spent = dict.fromkeys(TIMED, 0.0)
    saved = {name: getattr(L, name) for name in TIMED}
    stats0 = batch.engine._stats.sum(axis=0).copy()
    try:
        for name in TIMED:
            setattr(L, name, _timed(saved[name], spent, name))
        c0 = time.thread_time()
        loop.run(steps)
        total = time.thread_time() - c0
    finally:
        for name, fn in saved.items():
            setattr(L, name, fn)
    per = (batch.engine._stats.sum(axis=0) - stats0) / (steps * worlds)
    return {"agents": agents, "worlds": worlds, "trace": trace, "kernel": batch.kernel, "steps": steps,
            "cpu_us_per_world_step": round(1e6 * total / (steps * worlds), 2),
            **{f"{k}_share": round(v / total, 3) for k, v in spent.items()},
            **{name: round(float(v), 1) for name, v in zip(STAT_NAMES, per)}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--agents", default="20")
    p.add_argument("--worlds", default="256")
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--trace", action="store_true")
    a = p.parse_args()
    for n in (int(x) for x in a.agents.split(",")):
        for w in (int(x) for x in a.worlds.split(",")):
            print(json.dumps(split(n, w, a.steps, a.trace)), flush=True)


if __name__ == "__main__":
    main()
