"""The child process of `tracelab bench engine`'s start-up figures: `python -m tracelab.bench.probe
TARGET...` imports the engine, then for each target builds it and runs its first step, printing one JSON
line as soon as that step is done (the parent timestamps the lines: process start to first step).

Targets: `game` (an Engine on the program and facts of war.toml's advanced game, as its spec loads them),
`spec` (war.toml's base game: one DeclaredWorlds world and its first step), or the path of
a rule file. The last line reports how many compiled signatures `kernel.step_worlds` holds (one serves every
program: a new rule file must not recompile)."""
from __future__ import annotations

import json
import sys
import time

# deferred: the probe times the imports of what it measures (the engine, numpy, the simulator), and reads the kernel
# after the timed steps


def _first_step(target: str) -> tuple[float, float, float]:
    """(import s, build s, first step s) of one target, in this process."""
    t0 = time.perf_counter()
    from tracelab.engine import Engine, load_program
    if target == "spec":
        import numpy as np

        from tracelab.bench.sims import team_spec
        from tracelab.envs.declared.vector_world import DeclaredWorlds
    else:
        from tracelab.envs.declared.gridwar import WAR_SPEC
        from tracelab.envs.declared.spec import load_spec
    t1 = time.perf_counter()
    if target == "spec":
        worlds = DeclaredWorlds(team_spec(1), 1)
        worlds.use_generators([np.random.default_rng(0)])
        worlds.reset(np.arange(1))
        t2 = time.perf_counter()
        worlds.step(np.zeros((1, worlds.n_agents), np.int64))
    else:
        program = load_spec(WAR_SPEC, advanced=True).program if target == "game" else load_program(target)
        engine = Engine(program, worlds=1, trace=True)
        t2 = time.perf_counter()
        engine.step()
    t3 = time.perf_counter()
    return t1 - t0, t2 - t1, t3 - t2


def main(argv: list[str]) -> int:
    for target in argv:
        import_s, build_s, step_s = _first_step(target)
        print(json.dumps({"target": target, "import_s": import_s, "build_s": build_s, "step_s": step_s}),
              flush=True)
    from tracelab.engine import kernel
    print(json.dumps({"signatures": len(kernel.step_worlds.signatures)}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
