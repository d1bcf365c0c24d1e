"""Runs for the trace store's tests.

walk_run: the real engine on tests/data/store_walk.rules, three worlds played as three episodes
(ids 10, 11, 12: the store keeps the caller's ids):
  episode 10 (world 0): moves at t=1 and t=2, stops at t=3: a -> b -> c, alarm(r1) at t=3, outcome win
  episode 11 (world 1): never moves, outcome truncated
  episode 12 (world 2): moves from t=1 on: a -> b -> c -> d, outcome loss
synthetic_trace / synthetic_vocabulary (from tracelab.store.bench): data in the engine's documented format,
for volume (live reading, crashes)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from patience import PATIENCE
from tracelab.engine import Engine, load_program

from tracelab.store.bench import synthetic_trace, synthetic_vocabulary  # noqa: F401 - re-exported for tests
from tracelab.store.writer import TraceWriter

WALK_RULES = Path(__file__).resolve().parent / "data" / "store_walk.rules"
WALK_EPISODES = (10, 11, 12)
WALK_STEPS = 6
WALK_OUTCOMES = {10: "win", 11: "truncated", 12: "loss"}


def run_rows(run: Path, sql: str) -> list[tuple]:
    """The rows of `sql` over a run, read through the store's sandboxed path."""
    from tracelab.store import open_run
    con = open_run(run)
    try:
        return con.execute(sql).fetchall()
    finally:
        con.close()


def walk_action(world: int, t: int) -> int:
    """1 = move along the path, 0 = stay."""
    if world == 0:
        return int(t in (1, 2))
    if world == 2:
        return int(t >= 1)
    return 0


def write_walk_run(run_dir: Path, rules: Path = WALK_RULES, **writer_options: object) -> Path:
    """The walk (see above) on `rules`: store_walk.rules or a variant with the same `move(r1)` action."""
    program = load_program(str(rules))
    eng = Engine(program, worlds=len(WALK_EPISODES))
    episodes = np.array(WALK_EPISODES)
    meta = {"command": "pytest walk", "scenario": "walk", "rule_files": [str(rules)], "seed": 7,
            "config": {"worlds": 3}}
    with TraceWriter(run_dir, meta, **writer_options) as w:
        w.write_engine_program(eng)
        for world, ep in enumerate(WALK_EPISODES):
            w.begin_episode(ep, world=world, t_start=0, seed=world)
        move = eng.atom("move", "r1")
        previous = {world: 0 for world in range(len(WALK_EPISODES))}
        for t in range(WALK_STEPS):
            for world in range(len(WALK_EPISODES)):
                a = walk_action(world, t)
                if a != previous[world]:  # the action is an external fact, set when it changes
                    eng.add_fact(move, float(a), float(a), world=world)
                    previous[world] = a
            eng.step()
            w.write_engine(episodes, eng)
            for world, ep in enumerate(WALK_EPISODES):
                w.write_steps(ep, {"step": t, "t": t, "agent": "r1", "action": walk_action(world, t),
                                   "reward": -2.0, "obs": [[t, world]],
                                   "truncated": t == WALK_STEPS - 1 and ep == 11})
            w.write_metrics(t, {"loss": 1.0 / (t + 1), "epsilon": 0.5})
        for ep in WALK_EPISODES:
            w.end_episode(ep, steps=WALK_STEPS, outcome=WALK_OUTCOMES[ep],
                          reward=250.0 if ep == 10 else -12.0, rewards={"r1": 1.0}, t_end=WALK_STEPS - 1)
    return run_dir


def episode_rows(episode: int) -> int:
    """How many rows the live/crash writer process writes for an episode (checked by the readers)."""
    return 300 + 7 * episode


def live_and_sealed_walk_runs(base: Path) -> dict[str, Path]:
    """The walk run twice under `base`: 'live' (Parquet parts) and 'sealed' (run.duckdb)."""
    from tracelab.store.seal import seal_run
    runs = {"live": write_walk_run(base / "live"), "sealed": write_walk_run(base / "sealed")}
    seal_run(runs["sealed"])
    return runs


def tampered_copy(run: Path, dest: Path, *statements: str) -> Path:
    """A copy (at `dest`) of a sealed run whose file was changed by `statements`, run with plain DuckDB:
    what a stranger would do to the file before sharing it."""
    import shutil

    import duckdb
    copy = Path(shutil.copytree(run, dest))
    con = duckdb.connect(str(copy / "run.duckdb"))
    try:
        for s in statements:
            con.execute(s)
    finally:
        con.close()
    return copy


# ---- Ctrl-C on a command that runs a long query -----------------------------------------------------------

TRACELAB = [sys.executable, "-c", "import sys; from tracelab.cli import main; sys.exit(main())"]


def _duckdb_loaded(pid: int) -> bool:
    """Whether the process has loaded DuckDB's library: a reading command does so just before it opens the
    run and starts its queries."""
    return "_duckdb" in Path(f"/proc/{pid}/maps").read_text()


def _cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of a running process, all its threads (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def ctrl_c_after_start(argv: list[str], running_for: float = 3.0) -> tuple[int, list[str], float]:
    """`tracelab ARGV` in a subprocess, sent SIGINT (Ctrl-C) `running_for` seconds after it loaded DuckDB
    (into its query, even on a loaded machine; it must still be running then). Returns its exit status,
    its stderr's lines and the CPU seconds it spent from the signal to its end: CPU, not wall time, so that
    a loaded machine does not make a prompt stop look slow (a query that ran on would spend many more)."""
    proc = subprocess.Popen([*TRACELAB, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + PATIENCE
        while not _duckdb_loaded(proc.pid):
            assert proc.poll() is None and time.monotonic() < deadline, "the command did not start"
            time.sleep(0.05)
        time.sleep(running_for)
        assert proc.poll() is None, f"the command ended before Ctrl-C: {proc.communicate()}"
        before = _cpu_seconds(proc.pid)
        proc.send_signal(signal.SIGINT)
        with ThreadPoolExecutor(2) as pool:  # drain both pipes, as communicate() would, then reap with wait4
            out, err = pool.submit(proc.stdout.read), pool.submit(proc.stderr.read)
            err_text = err.result(timeout=PATIENCE)
            out.result(timeout=PATIENCE)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        return proc.returncode, err_text.strip().splitlines(), usage.ru_utime + usage.ru_stime - before
    finally:
        if proc.returncode is None:
            proc.kill()
            proc.communicate()
