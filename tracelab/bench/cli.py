"""`tracelab bench cli`: what a reading command costs a user who asks `why`, `trace`, `sql` over and over
(issue 40), beside the floor: `python -c "import duckdb; duckdb.sql('select 1').fetchall()"`, the least any
DuckDB-backed command can cost.

Each command runs in a fresh process, as a user runs it, on the sample runs (sample_runs/ of the source
tree), with PYTHONDONTWRITEBYTECODE unset (a user's Python writes .pyc files; one unmeasured round writes
them first). A round runs every command once, the floor included, so that the machine's other load falls
on all of them alike; the figure is each command's median over --repeats rounds of its CPU seconds (user +
sys of the child and of what it waited for), and its ratio to the floor's median. Each goal (issue 40) is
a ratio; the verdict says whether the median met it. `start`: the CPU seconds `eval --games 50` and `train`
spend after their imports until their first step (tracelab/bench/start.py; goal: within 1 s). `tui`: `tracelab
tui sample_runs/advanced`'s first screen drawn in textual's pilot (bench tui's first figure, a fresh process
each; goal: within 1 s, read as CPU seconds, which hold under load, beside the wall clock)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import tracelab
from tracelab.bench import start
from tracelab.bench.common import children_cpu_s, fmt_num, format_table, machine_info, sample_runs_dir, summarize
from tracelab.bench.tui import first_screen
from tracelab.provenance import load_average

FLOOR = ("python", "-c", "import duckdb; duckdb.sql('select 1').fetchall()")
COMPARED_RUNS = 10  # compare's figure: this many training runs side by side (copies of base-train)
TIMEOUT_S = 600
TUI_FIRST_SCREEN_GOAL_S = 1.0  # issue 40: the TUI's first screen drawn within 1 s of its start


def commands(runs: Path, copies: Path) -> list[tuple[str, tuple[str, ...], float | None]]:
    """(name, argv after `tracelab`, the goal: at most this many times the floor) of each command timed."""
    play, rules = str(runs / "advanced"), Path(tracelab.__file__).resolve().parents[1] / "rules"
    trained = [str(copies / f"train-{i:02d}") for i in range(1, COMPARED_RUNS + 1)]
    return [
        ("sql", ("sql", play, "SELECT 1"), 1.5),
        ("trace", ("trace", play, "--episode", "0", "--from", "1", "--to", "4"), 1.5),
        ("why", ("why", play, "captured(blue)", "--episode", "0", "--at", "21", "--depth", "3"), 1.5),
        ("why-not", ("why-not", play, "--rule", "snap_at", "--episode", "0", "--at", "21"), 1.5),
        ("why --action", ("why", str(runs / "base-train"), "--action", "red-agent-1", "--episode", "776", "--at", "2"),
         1.5),
        ("show", ("show", play), 1.5),
        ("check", ("check", play), 1.5),
        ("diff", ("diff", play, "0", "1"), None),
        ("runs", ("runs", str(runs)), 2.0),
        (f"compare ({COMPARED_RUNS} runs)", ("compare", *trained), 2.0),
        ("reason", ("reason", str(rules / "examples" / "reach.rules"), "--steps", "5"), 2.0),
    ]


def _cpu_of(argv: list[str], env: dict[str, str]) -> float:
    before = children_cpu_s()
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
    cpu = children_cpu_s() - before
    if done.returncode != 0:
        raise RuntimeError(f"`{' '.join(argv)}` failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    return cpu


def run(quick: bool, repeats: int, only: Sequence[str] | None = None) -> dict[str, Any]:
    """`only`: the names of the commands to time (the floor is always timed); None: all."""
    runs = sample_runs_dir()
    repeats = 1 if quick else repeats
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    load_before = load_average()
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-cli-") as tmp:
        copies = Path(tmp)
        for i in range(1, COMPARED_RUNS + 1):
            shutil.copytree(runs / "base-train", copies / f"train-{i:02d}")
        timed = [("floor", [sys.executable, *FLOOR[1:]], None)] + [
            (name, [sys.executable, "-m", "tracelab", *argv], goal) for name, argv, goal in commands(runs, copies)
            if only is None or name.split()[0] in only]
        for _, argv, _ in timed:  # writes the .pyc files a user's first run writes; not measured
            _cpu_of(argv, env)
        cpu: dict[str, list[float]] = {name: [] for name, _, _ in timed}
        for _ in range(repeats):
            for name, argv, _ in timed:
                cpu[name].append(_cpu_of(argv, env))
    starts = start.run(runs, repeats) if only is None or "start" in only else []
    first_screen = _tui_first_screen(runs, repeats) if only is None or "tui" in only else None
    floor = summarize(cpu["floor"]).median
    rows = []
    for name, argv, goal in timed:
        s = summarize(cpu[name])
        ratio = s.median / floor
        shown = " ".join(["python", *FLOOR[1:]] if name == "floor" else ["tracelab", *argv[3:]])
        shown = shown.replace(f"{runs.parent}/", "").replace(str(copies), "COPIES")
        rows.append({"name": name, "command": shown,
                     "cpu_s": s.to_dict(), "ratio": ratio, "goal": goal,
                     "met": None if goal is None else ratio <= goal})
    return {"repeats": repeats, "floor_cpu_s": floor, "commands": rows, "start": starts,
            "tui_first_screen": first_screen, "load_before": load_before, "load_after": load_average(),
            "machine": machine_info()}


def _tui_first_screen(runs: Path, repeats: int) -> dict[str, Any]:
    r = first_screen(runs / "advanced", repeats)
    return {**r, "goal_s": TUI_FIRST_SCREEN_GOAL_S, "met": r["cpu_s"]["median"] <= TUI_FIRST_SCREEN_GOAL_S}


def report(r: dict[str, Any]) -> str:
    table = [(c["name"], c["cpu_s"]["median"], f"{fmt_num(c['cpu_s']['min'])}-{fmt_num(c['cpu_s']['max'])}",
              f"{c['ratio']:.2f}x", "-" if c["goal"] is None else f"<= {c['goal']:g}x",
              {None: "-", True: "met", False: "NOT met"}[c["met"]]) for c in r["commands"]]
    lines = [f"CPU seconds (user+sys) of one process per command, medians of {r['repeats']} rounds; "
             f"load average before: {', '.join(map(str, r['load_before']))}, after: "
             f"{', '.join(map(str, r['load_after']))}",
             format_table(["command", "CPU s", "range", "x floor", "goal", "verdict"], table),
             "commands (RUN: sample_runs/advanced; compare: copies of sample_runs/base-train):"]
    lines += [f"  {c['name']}: {c['command']}" for c in r["commands"]]
    if r.get("start"):
        lines += ["start: CPU s after the imports until the first step (goal <= 1 s), and of the imports",
                  format_table(["command", "to first step", "imports", "verdict"],
                               [(s["name"], s["to_first_step_cpu_s"]["median"], s["imports_cpu_s"]["median"],
                                 "met" if s["met"] else "NOT met") for s in r["start"]])]
    if r.get("tui_first_screen"):
        t = r["tui_first_screen"]
        cpu = t["cpu_s"]
        lines += [f"tui: `tracelab tui sample_runs/advanced`'s first screen in textual's pilot, fresh processes "
                  f"(goal <= {t['goal_s']:g} s of CPU)",
                  format_table(["first screen", "CPU s", "CPU range", "wall s from spawn", "verdict"],
                               [("tui", cpu["median"], f"{fmt_num(cpu['min'])}-{fmt_num(cpu['max'])}",
                                 t["wall_s"]["median"], "met" if t["met"] else "NOT met")])]
    return "\n".join(lines)
