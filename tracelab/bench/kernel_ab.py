"""Two engine kernels on the same workload, in one process, in alternating blocks (CPU time):
`python -m tracelab.bench.kernel_ab [--agents 1,5] [--worlds 1] [--steps 2000] [--rounds 9]
[--kernels counting,compiled]`.

On a shared, loaded machine the wall-clock figures of two separate `bench env` runs move by more than
the difference between kernels; a paired ratio of CPU times, alternating A and B, does not. For each
(agents, worlds, trace) one batch of war.toml worlds (tracelab.bench.sims: war.toml's base game) is
built per kernel and stepped by the same seeded loop (sims.SpecLoop), blocks alternating A, B / B, A.
Prints one JSON line per case: the median CPU µs per world-step of each kernel and the median of the
paired ratios B/A (below 1: B is faster)."""
from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

from tracelab.bench.sims import SpecLoop, team_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds


def _block(loop: SpecLoop, steps: int) -> float:
    c0 = time.process_time()
    loop.run(steps)
    return time.process_time() - c0


def compare(agents: int, worlds: int, trace: bool, steps: int, rounds: int, kernels: list[str]) -> dict[str, Any]:
    spec = team_spec(agents)
    loops = []
    for k in kernels:
        batch = DeclaredWorlds(spec, worlds, kernel=k)
        assert batch.kernel == k, (k, batch.kernel, batch.engine.kernel_notice)
        loops.append(SpecLoop(batch, trace))
    for loop in loops:
        loop.run(steps)  # warm-up (first calls, caches)
    times: list[list[float]] = [[] for _ in kernels]
    for i in range(rounds):
        order = range(len(kernels)) if i % 2 == 0 else reversed(range(len(kernels)))
        for j in order:
            times[j].append(_block(loops[j], steps))
    us = [1e6 * float(np.median(t)) / (steps * worlds) for t in times]
    ratio = float(np.median(np.asarray(times[1]) / np.asarray(times[0])))
    return {"agents": agents, "worlds": worlds, "trace": trace, "steps": steps,
            **{f"{k}_cpu_us_per_world_step": round(u, 2) for k, u in zip(kernels, us)},
            f"{kernels[1]}_over_{kernels[0]}": round(ratio, 3), "rounds": rounds}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--agents", default="1,5")
    p.add_argument("--worlds", default="1")
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--kernels", default="counting,compiled")
    a = p.parse_args()
    kernels = a.kernels.split(",")
    for n in (int(x) for x in a.agents.split(",")):
        for w in (int(x) for x in a.worlds.split(",")):
            for trace in (False, True):
                print(json.dumps(compare(n, w, trace, max(1, a.steps // w), a.rounds, kernels)), flush=True)


if __name__ == "__main__":
    main()
