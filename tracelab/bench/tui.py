"""`tracelab bench tui`: first, the first screen of `tracelab tui sample_runs/advanced` in a fresh process
(tracelab.bench.tui_first_screen: `TracelabApp([run]).run_test(size=(120, 40))` until the episodes table
`#ep-table` has a cursor; wall seconds from spawning the process, its CPU seconds from its start, imports
included; goal: drawn within 1 s, issue 40). Then the terminal UI on a large run, timed through the app itself
in textual's headless pilot (the same widgets, workers and queries a user drives; keys are sent with
App.simulate_key, since Pilot.press waits for the process to look idle, up to a second per key, which would
time the wait): open the run, open a 10M-row episode's trace (first page shown), scroll to an uncached page,
jump to a timestep, filter by rule and by atom, and move to the atom's next change. Medians of several
repeats.

The run is synthetic (tracelab.store.bench's engine-format rows: one episode, 10 changes a step over
1,000 atoms, caused by facts and actions), written with TraceWriter and sealed; it is cached in the temp
directory between runs (keyed by its row count)."""
from __future__ import annotations

import asyncio
import json
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tracelab.bench.common import format_table, machine_info, sample_runs_dir, summarize
from tracelab.bench.engine import machine_line
from tracelab.store.bench import synthetic_trace, synthetic_vocabulary
from tracelab.store.seal import seal_run
from tracelab.store.writer import TraceWriter
from tracelab.viewers.tui.app import TracelabApp
from tracelab.viewers.tui.lazy_table import LazyTable
from tracelab.viewers.tui.paging import PAGE
from tracelab.viewers.tui.trace_paging import TraceFilter, TraceSource
from tracelab.viewers.tui.source import RunSource
from tracelab.viewers.tui.trace import TracePane

GOAL_FIRST_SCREEN_S = 1.0
GOAL_OPEN_S = 2.0
GOAL_PAGE_S = 0.2
BATCH = 250_000


def bench_run(rows: int, directory: Path | None = None) -> Path:
    """A sealed synthetic run of `rows` change rows in one episode (made once, then reused)."""
    root = directory or Path(tempfile.gettempdir()) / "tracelab-bench-tui"
    run = root / f"changes-{rows}"
    if (run / "run.duckdb").exists():
        return run
    shutil.rmtree(run, ignore_errors=True)
    root.mkdir(parents=True, exist_ok=True)
    with TraceWriter(run, {"command": f"tracelab bench tui ({rows:,} rows)"}) as w:
        w.write_vocabulary(synthetic_vocabulary())
        w.begin_episode(0, t_start=0, seed=0)
        written = 0
        while written < rows:
            n = min(BATCH, rows - written)
            written += w.write_changes(0, synthetic_trace(n, t0=written // 10, seed=written // BATCH))
        w.end_episode(0, steps=rows // 10, outcome="win", reward=1.0, t_end=(rows - 1) // 10)
    seal_run(run)
    return run


async def _until(pilot: Any, done: Callable[[], bool], timeout: float = 60.0) -> None:
    t0 = time.perf_counter()
    while not done():
        await asyncio.sleep(0.002)  # not pilot.pause(): that waits for every widget's queue, ~50 ms
        if time.perf_counter() - t0 > timeout:
            raise TimeoutError("the TUI did not answer within the benchmark's timeout")


async def _focus(pilot: Any, app: Any, key: str, widget_id: str) -> None:
    """Press `key` and wait until it focused the input `widget_id` (untimed: typing takes longer)."""
    app.simulate_key(key)
    await _until(None, lambda: app.focused is not None and app.focused.id == widget_id)
    await pilot.pause()  # let the focus change finish repainting


async def _session(run: Path, seed: int) -> dict[str, float]:
    """One pass through the app; seconds per action."""
    rng = random.Random(seed)
    out: dict[str, float] = {}
    t0 = time.perf_counter()
    app = TracelabApp([run])
    async with app.run_test(size=(120, 40)) as pilot:
        episodes = app.screen.query_one("#ep-table", LazyTable)
        await _until(pilot, lambda: episodes.idle and episodes.cursor_row is not None)
        out["open run (episodes shown)"] = time.perf_counter() - t0

        t1 = time.perf_counter()
        app.simulate_key("enter")
        await _until(pilot, lambda: bool(app.screen.query("#tr-table")))  # the Trace view is made on first use
        trace = app.screen.query_one("#tr-table", LazyTable)
        pane = app.screen.query_one(TracePane)
        loaded = lambda: trace.ready and trace.idle and (  # noqa: E731
            trace.count == 0 or trace.cursor_row is not None)
        await _until(pilot, lambda: trace.count > 0 and loaded())
        out["open trace (first page shown)"] = time.perf_counter() - t1
        out["open total"] = time.perf_counter() - t0

        t1 = time.perf_counter()
        await _until(pilot, lambda: pane.trace is not None and pane.trace.anchors is not None)
        out["page index ready (background)"] = time.perf_counter() - t1

        t1 = time.perf_counter()
        trace.move_to(rng.randrange(trace.count // 4, trace.count))
        await _until(pilot, loaded)
        out["scroll to an uncached page"] = time.perf_counter() - t1

        t1 = time.perf_counter()
        app.simulate_key("pagedown")
        await _until(pilot, loaded)
        out["page down"] = time.perf_counter() - t1

        target_t = rng.randrange(1, int(trace.count // 10))
        jumps = pane.jumps
        pane.query_one("#tr-goto").value = str(target_t)
        await _focus(pilot, app, "g", "tr-goto")
        t1 = time.perf_counter()
        app.simulate_key("enter")
        await _until(pilot, lambda: pane.jumps > jumps and loaded())
        out["jump to a timestep"] = time.perf_counter() - t1
        assert trace.cursor_row is not None and trace.cursor_row["t"] == target_t

        jumps = pane.jumps
        t1 = time.perf_counter()
        app.simulate_key("n")
        await _until(pilot, lambda: pane.jumps > jumps and loaded())
        out["next change of the atom"] = time.perf_counter() - t1

        pane.query_one("#tr-rule").value = "action"
        await _focus(pilot, app, "slash", "tr-atom")
        t1 = time.perf_counter()
        app.simulate_key("enter")
        await _until(pilot, lambda: loaded() and pane.filter is not None and pane.filter.rule == "action")
        out["filter by rule (half the rows)"] = time.perf_counter() - t1

        atom = trace.cursor_row["atom"]
        pane.query_one("#tr-rule").value = ""
        pane.query_one("#tr-atom").value = atom
        await _focus(pilot, app, "slash", "tr-atom")
        t1 = time.perf_counter()
        app.simulate_key("enter")
        await _until(pilot, lambda: loaded() and pane.filter is not None and pane.filter.atom == atom)
        assert trace.count > 0
        out["filter by atom"] = time.perf_counter() - t1
    return out


def _queries(run: Path, seed: int) -> dict[str, float]:
    """The same steps at the paging layer alone (TraceSource, no app): what DuckDB costs."""
    rng = random.Random(seed)
    source = RunSource(run)
    out: dict[str, float] = {}

    def timed(name: str, fn: Callable[[], Any]) -> Any:
        t0 = time.perf_counter()
        result = fn()
        out[name] = time.perf_counter() - t0
        return result

    trace = TraceSource(source, TraceFilter(0))
    count = timed("open trace (count, first page)", lambda: (trace.prepare(), trace.fetch(0))[0])
    timed("page index (anchors)", trace.warm)
    timed("scroll to an uncached page", lambda: trace.fetch(rng.randrange(count // 4, count) // PAGE))
    row = timed("jump to a timestep", lambda: trace.row_of_t(rng.randrange(1, count // 10)))
    trace.fetch(row // PAGE)
    seq = int(trace.fetch(row // PAGE)[row % PAGE]["seq"])
    timed("next change of the atom", lambda: trace.next_change(int(trace.fetch(row // PAGE)[row % PAGE]["atom_id"]),
                                                               seq, True))
    for name, flt in (("filter by rule (half the rows)", TraceFilter(0, rule="action")),
                      ("filter by atom", TraceFilter(0, atom=str(trace.fetch(row // PAGE)[row % PAGE]["atom"])))):
        filtered = TraceSource(source, flt, ("seq", seq))
        timed(name, lambda f=filtered: (f.prepare(), f.fetch(f.start_row // PAGE)))
    source.close()
    return out


def first_screen(run: Path, repeats: int) -> dict[str, Any]:
    """`tracelab tui RUN`'s first screen drawn, in fresh processes (one unmeasured first: .pyc files are
    written as a user's Python writes them): wall s from spawning each, CPU s of each from its start."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    wall, cpu = [], []
    for i in range(repeats + 1):
        spawned = time.time()
        out = subprocess.run([sys.executable, "-m", "tracelab.bench.tui_first_screen", str(run)], env=env,
                             capture_output=True, text=True, timeout=600, check=True)
        done = json.loads(out.stdout.splitlines()[-1])
        if i:
            wall.append(done["wall_at"] - spawned)
            cpu.append(done["cpu_s"])
    return {"run": str(run), "wall_s": summarize(wall).to_dict(), "cpu_s": summarize(cpu).to_dict()}


def run(quick: bool = False, repeats: int = 5, rows: int | None = None) -> dict[str, Any]:
    os.environ.setdefault("TEXTUAL_ANIMATIONS", "none")
    first = first_screen(sample_runs_dir() / "advanced", max(1, repeats))
    rows = rows or (200_000 if quick else 10_000_000)
    t0 = time.perf_counter()
    path = bench_run(rows)
    made_s = time.perf_counter() - t0
    sessions = [asyncio.run(_session(path, seed)) for seed in range(max(1, repeats))]
    figures = {k: summarize([s[k] for s in sessions]).to_dict() for k in sessions[0]}
    alone = [_queries(path, seed) for seed in range(max(1, repeats))]
    queries = {k: summarize([q[k] for q in alone]).to_dict() for k in alone[0]}
    return {"machine": machine_info(), "quick": quick, "repeats": repeats, "rows": rows, "first_screen": first,
            "run": str(path), "run_ready_s": made_s, "figures": figures, "queries_alone": queries}


def report(r: dict[str, Any]) -> str:
    first = r["first_screen"]
    wall, cpu = first["wall_s"], first["cpu_s"]
    first_table = format_table(
        ["first screen, fresh process (tracelab tui RUN)", "median s", "min s", "max s", "goal s", "met"],
        [["wall, from spawning it", wall["median"], wall["min"], wall["max"], GOAL_FIRST_SCREEN_S,
          "yes" if wall["median"] <= GOAL_FIRST_SCREEN_S else "NO"],
         ["CPU, from its start", cpu["median"], cpu["min"], cpu["max"], "", ""]])
    rows = []
    for name, s in r["figures"].items():
        goal = GOAL_OPEN_S if name.startswith(("open", "page index")) else GOAL_PAGE_S
        rows.append([name, 1000 * s["median"], 1000 * s["min"], 1000 * s["max"], 1000 * goal,
                     "yes" if s["median"] <= goal else "NO"])
    table = format_table(["action (headless pilot)", "median ms", "min ms", "max ms", "goal ms", "met"], rows)
    alone = format_table(["the same, queries alone (TraceSource)", "median ms", "min ms", "max ms"],
                         [[k, 1000 * s["median"], 1000 * s["min"], 1000 * s["max"]]
                          for k, s in r["queries_alone"].items()])
    return (machine_line(r["machine"], r["quick"], r["repeats"]) + f"\n{first['run']}\n\n" + first_table +
            f"\n\n{r['rows']:,} change rows in one episode ({r['run']})\n\n" + table + "\n\n" + alone)
