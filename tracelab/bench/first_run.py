"""`tracelab bench first-run`: what a newcomer waits for (issue 31 part 4). The README's main command,
`tracelab play --scenario advanced --episodes 5`, runs in a fresh process on empty caches, as after a
fresh install (numba's through NUMBA_CACHE_DIR, tracelab's compile cache through TRACELAB_CACHE_DIR, both
in a temporary folder: the user's own caches are neither read nor touched), then once more on the caches
it filled, as every later run does. Each figure is the median of --repeats such pairs: wall time, and
CPU time (user + sys of the command and of every process it waited for, such as the second process that
compiles the game's kernels), which the other load of a shared machine inflates far less than wall time.
The load average before and after is part of the result."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from typing import Any

from tracelab.bench.common import children_cpu_s, fmt_num, format_table, machine_info, summarize
from tracelab.provenance import load_average

COMMAND = ("play", "--scenario", "advanced", "--episodes", "5")
QUICK_COMMAND = ("play", "--scenario", "advanced", "--episodes", "1")
TIMEOUT_S = 1800  # a cold compile on a loaded machine has taken 3 minutes of wall time


def timed_command(command: tuple[str, ...], cache_dir: str, run_dir: str) -> dict[str, Any]:
    """One `tracelab COMMAND --run RUN_DIR` in a fresh process with its caches in `cache_dir`: wall and CPU
    seconds, and the compile notice it printed (the lines of stderr that start with it)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": os.path.join(cache_dir, "numba"),
           "TRACELAB_CACHE_DIR": os.path.join(cache_dir, "tracelab")}
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    done = subprocess.run([sys.executable, "-P", "-m", "tracelab", *command, "--run", run_dir], env=env,
                          capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - cpu0
    if done.returncode != 0:
        raise RuntimeError(f"`tracelab {' '.join(command)}` failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    notice = [ln for ln in done.stderr.splitlines() if ln.startswith("tracelab: compiling")]
    return {"wall_s": wall, "cpu_s": cpu, "notice": notice}


def run(quick: bool, repeats: int) -> dict[str, Any]:
    command = QUICK_COMMAND if quick else COMMAND
    repeats = 1 if quick else repeats
    load_before = load_average()
    cold, warm = [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="tracelab-first-run-") as tmp:
            cold.append(timed_command(command, tmp, os.path.join(tmp, "run-cold")))
            warm.append(timed_command(command, tmp, os.path.join(tmp, "run-warm")))
    return {"command": "tracelab " + " ".join(command), "repeats": repeats,
            "cold_wall_s": summarize([r["wall_s"] for r in cold]).to_dict(),
            "cold_cpu_s": summarize([r["cpu_s"] for r in cold]).to_dict(),
            "warm_wall_s": summarize([r["wall_s"] for r in warm]).to_dict(),
            "warm_cpu_s": summarize([r["cpu_s"] for r in warm]).to_dict(),
            "cold_notice": cold[0]["notice"], "warm_notice": warm[0]["notice"],
            "load_before": load_before, "load_after": load_average(), "machine": machine_info()}


def report(r: dict[str, Any]) -> str:
    rows = [(which, r[f"{which}_wall_s"]["median"], r[f"{which}_cpu_s"]["median"],
             f"{fmt_num(r[f'{which}_wall_s']['min'])}-{fmt_num(r[f'{which}_wall_s']['max'])}")
            for which in ("cold", "warm")]
    load = ", ".join(map(str, r["load_before"])) or "?"
    lines = [f"{r['command']}, medians of {r['repeats']} (cold: empty caches, as a fresh install; warm: "
             f"the caches it filled); load average before: {load}, after: {', '.join(map(str, r['load_after']))}",
             format_table(["caches", "wall s", "CPU s (user+sys)", "wall range"], rows),
             "notice on a cold run: " + (" / ".join(r["cold_notice"]) or "(none)")]
    if r["warm_notice"]:
        lines.append("notice on a warm run (there should be none): " + " / ".join(r["warm_notice"]))
    return "\n".join(lines)
