"""This tree's spec path against another tree's, on bench env's workload (tracelab.bench.sims.SpecLoop over
the war game's spec), in two processes stepping in turn: `python -m tracelab.bench.tree_ab --other
/tmp/venv_main/bin/python [--agents 5,20] [--worlds 1] [--steps 6000] [--rounds 15] [--trace]`.

For a change spread over modules that cannot be loaded twice in one process (the engine, the envs, the
kernels' glue): each interpreter (`--other`: one whose tracelab is the other tree, e.g. a venv with it
installed editable; this one: sys.executable) builds its own batch of the same spec and seeds, warms it up,
then steps a block whenever asked; blocks alternate A, B / B, A and each is timed by its own process's CPU
time. Prints one JSON line per case: each tree's median env-steps per CPU second and the median of the
paired ratios this / other (above 1: this tree is faster)."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from typing import Any

import numpy as np

# what each process runs: only names that both trees have (sims.SpecLoop, team_spec, DeclaredWorlds)
CHILD = """
import sys, time
from tracelab.bench.sims import SpecLoop, team_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds
agents, worlds, steps, trace = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "on"
loop = SpecLoop(DeclaredWorlds(team_spec(agents), worlds), trace)
loop.run(steps)
print("ready", flush=True)
for _ in sys.stdin:
    c0 = time.process_time()
    loop.run(steps)
    print(time.process_time() - c0, flush=True)
"""


def compare(other: str, agents: int, worlds: int, steps: int, rounds: int, trace: bool) -> dict[str, Any]:
    args = [str(agents), str(worlds), str(steps), "on" if trace else "off"]
    procs: list[subprocess.Popen[str]] = []
    try:
        for python in (sys.executable, other):
            procs.append(subprocess.Popen([python, "-c", CHILD, *args], stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, text=True))
        for p in procs:
            assert p.stdout is not None and p.stdout.readline().strip() == "ready", "a tree failed to start"
        times: list[list[float]] = [[], []]
        for i in range(rounds):
            for j in ((0, 1) if i % 2 == 0 else (1, 0)):
                p = procs[j]
                assert p.stdin is not None and p.stdout is not None
                p.stdin.write("block\n")
                p.stdin.flush()
                times[j].append(float(p.stdout.readline()))
    finally:
        for p in procs:
            if p.stdin is not None:
                p.stdin.close()
            p.kill()  # a child not yet ready (the other failed) has nothing to finish
            p.wait()
    rate = [steps * worlds / float(np.median(t)) for t in times]
    ratio = float(np.median(np.asarray(times[1]) / np.asarray(times[0])))
    return {"agents": agents, "worlds": worlds, "trace": trace, "steps": steps, "rounds": rounds,
            "this_env_steps_per_cpu_s": round(rate[0]), "other_env_steps_per_cpu_s": round(rate[1]),
            "this_over_other": round(ratio, 3)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--other", required=True, help="the other tree's python (its tracelab installed)")
    p.add_argument("--agents", default="5,20")
    p.add_argument("--worlds", default="1")
    p.add_argument("--steps", type=int, default=6000, help="world-steps a block (divided by agents and worlds)")
    p.add_argument("--rounds", type=int, default=15)
    p.add_argument("--trace", action="store_true")
    a = p.parse_args()
    for n in (int(x) for x in a.agents.split(",")):
        for w in (int(x) for x in a.worlds.split(",")):
            try:
                row = compare(a.other, n, w, max(1, a.steps // (n * w)), a.rounds, a.trace)
            except OSError as e:  # --other is not a python
                p.error(f"--other {a.other}: {e.strerror}")
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
