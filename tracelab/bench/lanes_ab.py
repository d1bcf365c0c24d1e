"""This tree's lanes kernel (engine/lanes.py) against another tree's, in one process, on bench env's
workload (tracelab.bench.sims.SpecLoop over the war game's spec): `python -m tracelab.bench.lanes_ab
--other /work/main/engine/lanes.py --agents 20 --worlds 256 [--steps 20] [--rounds 7] [--trace]`.

The other file is compiled here without numba's disk cache (nothing is written beside it) and has to keep
this tree's signatures (backend_lanes calls it as its own), but for step_lanes: where its parameters differ,
it is given this tree's arguments by name (one that takes more tables than this tree has fails at its call).
Each kernel steps its own batch (the same spec and seeds); blocks alternate A, B / B, A and are timed by
this thread's CPU time. Prints one JSON line per case: the median CPU µs per world-step of each and the
median of the paired ratios other / this (above 1: this tree is faster)."""
from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import sys
import time
from pathlib import Path
from types import ModuleType, SimpleNamespace
from typing import Any

import numpy as np

from tracelab.bench.sims import SpecLoop, team_spec
from tracelab.engine import backend_lanes
from tracelab.envs.declared.vector_world import DeclaredWorlds


def load_uncached(path: Path, name: str) -> ModuleType:
    """The lanes module at `path`, compiled in this process only (its cache=True turned off)."""
    source = path.read_text().replace("njit(cache=True,", "njit(cache=False,")
    spec = importlib.util.spec_from_loader(name, loader=None)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    exec(compile(source, str(path), "exec"), module.__dict__)  # noqa: S102 (a file of the project's own trees)
    return module


def by_name(other: ModuleType, mine: ModuleType) -> Any:
    """`other`, its step_lanes called with this tree's arguments picked by its own parameter names (an
    argument it does not know is left out; one it needs that this tree lacks raises a KeyError), and this
    tree's integer constants that it lacks (the backend names them, as ctl's C_SETTLED) or that size a
    table larger (N_CTL: the other kernel reads its own fields of it): a kernel that takes fewer tables
    (main's, against a branch's new ones) runs on this tree's backend."""
    have = list(inspect.signature(mine.step_lanes.py_func).parameters)
    want = list(inspect.signature(other.step_lanes.py_func).parameters)
    lacking = {k: v for k, v in vars(mine).items() if k.isupper() and type(v) is int
               and (not hasattr(other, k) or (k.startswith("N_") and v > getattr(other, k)))}
    if have == want and not lacking:
        return other

    def step_lanes(*args: Any) -> Any:
        named = dict(zip(have, args))
        return other.step_lanes(*(named[p] for p in want))
    return SimpleNamespace(**{**vars(other), **lacking, "step_lanes": other.step_lanes if have == want else step_lanes})


def _block(loop: SpecLoop, kernel: Any, steps: int) -> float:
    backend_lanes.L = kernel
    c0 = time.thread_time()
    loop.run(steps)
    return time.thread_time() - c0


def compare(other: Any, agents: int, worlds: int, trace: bool, steps: int, rounds: int) -> dict[str, Any]:
    mine = backend_lanes.L
    kernels = (mine, other)
    try:
        loops = []
        for kernel in kernels:
            backend_lanes.L = kernel
            batch = DeclaredWorlds(team_spec(agents), worlds, kernel="lanes")
            loops.append(SpecLoop(batch, trace))
        for loop, kernel in zip(loops, kernels):
            _block(loop, kernel, steps)  # warm-up: first calls, the grounding table's growth
        times: list[list[float]] = [[], []]
        for i in range(rounds):
            for j in ((0, 1) if i % 2 == 0 else (1, 0)):
                times[j].append(_block(loops[j], kernels[j], steps))
    finally:
        backend_lanes.L = mine
    us = [1e6 * float(np.median(t)) / (steps * worlds) for t in times]
    return {"agents": agents, "worlds": worlds, "trace": trace, "steps": steps, "rounds": rounds,
            "this_cpu_us_per_world_step": round(us[0], 2), "other_cpu_us_per_world_step": round(us[1], 2),
            "other_over_this": round(float(np.median(np.asarray(times[1]) / np.asarray(times[0]))), 3)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--other", type=Path, required=True)
    p.add_argument("--agents", default="20")
    p.add_argument("--worlds", default="256")
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--trace", action="store_true")
    a = p.parse_args()
    other = by_name(load_uncached(a.other, "tracelab_lanes_other"), backend_lanes.L)
    for n in (int(x) for x in a.agents.split(",")):
        for w in (int(x) for x in a.worlds.split(",")):
            print(json.dumps(compare(other, n, w, a.trace, a.steps, a.rounds)), flush=True)


if __name__ == "__main__":
    main()
