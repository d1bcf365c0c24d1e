"""How much CPU `tracelab eval --games N` and `tracelab train` spend before their first step, after their
imports (issue 40's goal: within 1 s). A fresh process imports what the command imports (timed apart: the
imports' figure), then runs the command through `tracelab.cli.main`; the vector env it steps (the declared
one, war.toml) reports the CPU seconds at its first step and ends the process there
(python -m tracelab.bench.start COMMAND). Warm caches: numba's, as the user's later runs find them (the first
run's compiles are `bench first-run`'s)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tracelab.bench.common import summarize

# what the commands import before their first step, loaded before the clock starts
IMPORTS = ("numpy", "torch", "numba", "duckdb", "gymnasium", "tracelab.cli", "tracelab.commands.eval",
           "tracelab.commands.train", "tracelab.envs.declared.vector_env", "tracelab.train.env_trainer",
           "tracelab.train.env_policy", "tracelab.store")
GOAL_S = 1.0
TIMEOUT_S = 600


def commands(runs: Path, run_dir: str) -> dict[str, list[str]]:
    return {"eval --games 50": ["eval", str(runs / "base-train" / "policy"), "--games", "50"],
            "train": ["train", "--scenario", "base", "--total-timesteps", "1000", "--run", run_dir]}


def _child(name: str, runs: Path) -> None:
    """In the child: import, then run the command until its env's first step; print the figures."""
    import importlib
    t0 = time.process_time()
    for module in IMPORTS:
        importlib.import_module(module)
    imported = time.process_time()
    from tracelab.cli import main
    from tracelab.envs.declared.vector_env import DeclaredVectorEnv

    def first_step(*_: Any) -> None:
        print(json.dumps({"imports_s": imported - t0, "to_first_step_s": time.process_time() - imported}),
              file=sys.__stdout__, flush=True)
        os._exit(0)  # the figure is taken: the rest of the command is not the start

    DeclaredVectorEnv.step = first_step  # type: ignore[method-assign]
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-start-") as tmp:
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (the process ends in first_step)
        main(commands(runs, os.path.join(tmp, "run"))[name])
    raise RuntimeError(f"{name} ended without stepping a vector env")


def run(runs: Path, repeats: int) -> list[dict[str, Any]]:
    """Each command's imports and start, CPU seconds, medians of `repeats` fresh processes."""
    rows = []
    for name in commands(runs, "RUN"):
        figures: dict[str, list[float]] = {"imports_s": [], "to_first_step_s": []}
        for _ in range(repeats):
            done = subprocess.run([sys.executable, "-m", "tracelab.bench.start", name, str(runs)],
                                  capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
            if done.returncode != 0 or not done.stdout.strip():
                raise RuntimeError(f"bench start of `{name}` failed:\n{done.stderr[-2000:]}")
            got = json.loads(done.stdout.strip().splitlines()[-1])
            for key in figures:
                figures[key].append(got[key])
        start = summarize(figures["to_first_step_s"])
        rows.append({"name": name, "imports_cpu_s": summarize(figures["imports_s"]).to_dict(),
                     "to_first_step_cpu_s": start.to_dict(), "goal_s": GOAL_S, "met": start.median <= GOAL_S})
    return rows


if __name__ == "__main__":
    _child(sys.argv[1], Path(sys.argv[2]))
