"""Two engine kernels on the same recorded work, in one process, in alternating blocks (CPU time):
`python -m tracelab.bench.kernel_ab [--agents 1,5] [--worlds 1] [--steps 2000] [--rounds 9]
[--kernels counting,compiled]`.

On a shared, loaded machine the wall-clock figures of two separate `bench env` runs move by more than
the difference between kernels; a paired ratio of CPU times, alternating A and B, does not. For each
(agents, worlds, trace) the RuleSim's stepping loop is recorded once (sims.record_replay: each step's
external rows and each restore) and replayed on one engine per kernel, from the same start state.
Prints one JSON line per case: the median CPU µs per world-step of each kernel and the median of the
paired ratios B/A (below 1: B is faster)."""
from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from tracelab.bench.sims import Loop, record_replay, scenario_for
from tracelab.game.rulesim import RuleSim


def _replayer(sim: RuleSim, trace: bool, steps: int) -> Callable[[], float]:
    """The CPU seconds of one replay of `steps` recorded steps of the stepping loop."""
    replay, _ = record_replay(Loop(sim, trace), steps)

    def timed() -> float:
        c0 = time.process_time()
        replay()
        return time.process_time() - c0
    return timed


def compare(agents: int, worlds: int, trace: bool, steps: int, rounds: int, kernels: list[str]) -> dict[str, Any]:
    replays = []
    for k in kernels:
        sim = RuleSim(scenario_for(agents), worlds, seed=0, trace=True, kernel=k)
        assert sim.engine.kernel == k, (k, sim.engine.kernel, sim.engine.kernel_notice)
        sim.engine.trace_on[:] = trace
        replays.append(_replayer(sim, trace, steps))
    for r in replays:
        r()  # warm-up
    times: list[list[float]] = [[] for _ in kernels]
    for i in range(rounds):
        order = range(len(kernels)) if i % 2 == 0 else reversed(range(len(kernels)))
        for j in order:
            times[j].append(replays[j]())
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
