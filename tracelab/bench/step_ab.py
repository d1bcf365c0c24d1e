"""RefSim and RuleSim's stepping loop, RuleSim's trace taken as before this branch (after every step) and
as now (when the envs' tracer takes it: tracer.handover_due), in one process, in alternating blocks (CPU
time): `python -m tracelab.bench.step_ab [--cases 1x1t,1x256,5x256,20x256,20x1t] [--steps 2000] [--rounds 7]`.

A case is AGENTSxWORLDS, with `t` for tracing on. Every simulator runs bench env's loop (sims.Loop:
fixed-seed random red, scripted blue, finished worlds reset) for `steps` world-steps a block; blocks
alternate A, B, C / C, B, A. `time.process_time` counts only this process's CPU, so the other processes
on a shared machine do not count. Prints one JSON line per case: median CPU µs per world-step of each,
the median paired ratio now / before, and RuleSim / RefSim in steps per CPU-second (the goals' measure,
docs/benchmarks.md), before and now. Untraced, before and now are the same loop (a check of the noise)."""
from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

from tracelab.bench.sims import Loop, scenario_for
from tracelab.game.refsim import RefSim
from tracelab.game.rulesim import RuleSim

VARIANTS = ("refsim", "rulesim_before", "rulesim_now")


class EveryStepLoop(Loop):
    """Loop with the trace taken after every step (the tracer before this branch)."""

    def _handover_due(self, episode_ended: bool) -> bool:
        return True


def _block(loop: Loop, steps: int) -> float:
    c0 = time.process_time()
    loop.run(steps)
    return time.process_time() - c0


def compare(agents: int, worlds: int, trace: bool, steps: int, rounds: int, kernel: str) -> dict[str, Any]:
    sc = scenario_for(agents)
    sims = [RefSim(sc, worlds, seed=0),
            RuleSim(sc, worlds, seed=0, trace=True, kernel=kernel),
            RuleSim(sc, worlds, seed=0, trace=True, kernel=kernel)]
    loops = [Loop(sims[0], trace), EveryStepLoop(sims[1], trace), Loop(sims[2], trace)]
    block = max(1, steps // worlds)
    for loop in loops:
        loop.run(block)  # warm-up (first calls, caches)
    times: list[list[float]] = [[] for _ in sims]
    for i in range(rounds):
        order = range(len(sims)) if i % 2 == 0 else reversed(range(len(sims)))
        for j in order:
            times[j].append(_block(loops[j], block))
    t = [np.asarray(x) for x in times]
    per = block * worlds
    return {"agents": agents, "worlds": worlds, "trace": trace, "kernel": sims[2].engine.kernel,
            "fused_used": sims[2].fused, "world_steps_per_block": per, "rounds": rounds,
            **{f"{v}_cpu_us": round(1e6 * float(np.median(x)) / per, 2) for v, x in zip(VARIANTS, t)},
            "now_over_before": round(float(np.median(t[2] / t[1])), 3),
            "ratio_before": round(float(np.median(t[0] / t[1])), 4),
            "ratio_now": round(float(np.median(t[0] / t[2])), 4)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cases", default="1x1t,1x256,5x256,20x256,20x1t")
    p.add_argument("--steps", type=int, default=2000, help="world-steps per block")
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--kernel", default="auto")
    a = p.parse_args()
    for case in a.cases.split(","):
        trace = case.endswith("t")
        n, w = (int(x) for x in case.rstrip("t").split("x"))
        print(json.dumps(compare(n, w, trace, a.steps, a.rounds, a.kernel)), flush=True)


if __name__ == "__main__":
    main()
