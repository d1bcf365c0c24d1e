"""Live reading and crash safety, with a real second process: one process writes a run while this one
reads it; writers are killed with SIGKILL and SIGTERM."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from patience import PATIENCE, wait_until
from store_helpers import episode_rows

from tracelab.store import layout
from tracelab.store.parts import read_manifest
from tracelab.store.reader import open_run, retrying, run_info
from tracelab.store.seal import seal_run

PROC = Path(__file__).resolve().parent / "store_proc.py"


def start_writer(mode: str, run_dir: Path, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(PROC), mode, str(run_dir), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_run(run_dir: Path, proc: subprocess.Popen, timeout: float = PATIENCE) -> None:
    deadline = time.monotonic() + timeout
    while not layout.meta_path(run_dir).exists():
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline, "the writer never created its run"
        time.sleep(0.02)


def check_consistent(con, complete_episodes: set[int] | None = None) -> int:  # noqa: ANN001
    """No row twice, no gap in the row numbers, every ended episode complete; returns the row count."""
    n, distinct, top = con.execute("SELECT count(*), count(DISTINCT seq), coalesce(max(seq) + 1, 0) "
                                   "FROM raw.changes").fetchone()
    assert n == distinct == top, (n, distinct, top)
    ended = con.execute("SELECT e.episode, (SELECT count(*) FROM raw.changes c WHERE c.episode = e.episode) "
                        "FROM episodes e WHERE e.ended").fetchall()
    for episode, rows in ended:
        assert rows == episode_rows(episode), (episode, rows)
    if complete_episodes is not None:
        assert complete_episodes <= {e for e, _ in ended}
    # every row's atom is already in the vocabulary (it is published first)
    assert con.execute("SELECT count(*) FROM changes WHERE atom IS NULL").fetchone()[0] == 0
    return n


def test_second_process_reads_a_run_while_it_is_written(tmp_path: Path) -> None:
    run_dir = tmp_path / "live"
    episodes = 30
    proc = start_writer("live", run_dir, str(episodes))
    try:
        wait_for_run(run_dir, proc)
        con = open_run(run_dir)  # one connection for the whole run: new parts show up by themselves
        seen: list[int] = []
        while proc.poll() is None:
            n = retrying(lambda: check_consistent(con))
            if proc.poll() is None:  # the writer was still running after the query
                seen.append(n)
            time.sleep(0.05)
        assert proc.returncode == 0, proc.stderr.read()
    finally:
        proc.kill()
    total = sum(episode_rows(e) for e in range(episodes))
    growing = sorted(set(seen))
    assert seen == sorted(seen), "a reader saw the row count go down"
    assert len([n for n in growing if 0 < n < total]) >= 3, f"too few intermediate states seen: {growing}"
    assert check_consistent(con, set(range(episodes))) == total
    assert con.execute("SELECT status FROM run").fetchone()[0] == "finished"  # as of the query
    assert run_info(run_dir).status == "finished"
    listed = read_manifest(run_dir)["changes"]
    written = list((run_dir / "parts" / "changes").glob("*.parquet"))
    assert len(listed) < episodes < len(written), "the writer should have compacted its parts while we read"


def _read_lines_until(proc: subprocess.Popen, predicate, timeout: float = PATIENCE) -> list[str]:  # noqa: ANN001
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    while not predicate(lines):
        assert time.monotonic() < deadline, f"writer too slow: {lines[-3:]}"
        line = proc.stdout.readline()
        assert line, f"writer exited: {proc.stderr.read()}"
        lines.append(line.strip())
    return lines


def test_sigkill_loses_nothing_committed_and_the_run_still_opens(tmp_path: Path) -> None:
    run_dir = tmp_path / "crash"
    proc = start_writer("crash", run_dir)
    try:
        lines = _read_lines_until(proc, lambda ls: len(ls) >= 6)
        time.sleep(0.013)  # land the kill somewhere inside the next episode
        proc.send_signal(signal.SIGKILL)
        proc.wait(PATIENCE)
        # the last lines it printed before dying
        lines += [ln.strip() for ln in proc.stdout.read().splitlines()]
    finally:
        proc.kill()
    committed = {int(ln.split()[1]) for ln in lines if ln.startswith("committed")}
    assert len(committed) >= 6
    info = run_info(run_dir)
    assert info.status == "crashed"
    con = open_run(run_dir)
    n = check_consistent(con, committed)
    assert n >= sum(episode_rows(e) for e in committed)
    steps = dict(con.execute("SELECT episode, count(*) FROM steps GROUP BY 1").fetchall())
    assert all(steps[e] == 5 for e in committed)
    con.close()
    # a crashed run can be sealed; the sealed file holds the same rows
    sealed = seal_run(run_dir)
    assert not list(run_dir.glob("parts/*/.*tmp*"))
    con = open_run(sealed)
    assert check_consistent(con, committed) == n
    assert con.execute("SELECT status FROM run").fetchone()[0] == "crashed"
    assert json.loads((run_dir / "meta.json").read_text())["status"] == "crashed"


def test_rows_are_published_without_any_call(tmp_path: Path) -> None:
    """The writer's process makes no call after its rows (it waits until killed): only the writer's own
    timer can publish them. How soon it does is `tracelab bench store`'s question, not this test's."""
    run_dir = tmp_path / "idle"
    proc = start_writer("idle", run_dir)
    try:
        _read_lines_until(proc, lambda ls: "wrote" in ls)
        con = open_run(run_dir)
        wait_until(lambda: con.execute("SELECT count(*) FROM raw.changes").fetchone()[0] >= 500,
                   "the idle writer's 500 rows visible to another process")
        proc.send_signal(signal.SIGKILL)
        proc.wait(PATIENCE)
    finally:
        proc.kill()
    assert open_run(run_dir).execute("SELECT count(*) FROM changes").fetchone()[0] == 500


def test_sigterm_flushes_and_marks_the_run_interrupted(tmp_path: Path) -> None:
    run_dir = tmp_path / "term"
    proc = start_writer("idle", run_dir)
    try:
        _read_lines_until(proc, lambda ls: "wrote" in ls)
        proc.send_signal(signal.SIGTERM)  # before the 1 s timer: only the exit path can flush
        assert proc.wait(PATIENCE) == 128 + signal.SIGTERM
    finally:
        proc.kill()
    info = run_info(run_dir)
    assert info.status == "interrupted"
    assert info.meta["ended_at"] is not None
    assert open_run(run_dir).execute("SELECT count(*) FROM changes").fetchone()[0] == 500


def test_sealing_a_run_being_written_is_refused(tmp_path: Path) -> None:
    run_dir = tmp_path / "busy"
    proc = start_writer("idle", run_dir)
    try:
        _read_lines_until(proc, lambda ls: "wrote" in ls)
        with pytest.raises(RuntimeError, match="still being written"):
            seal_run(run_dir)
        assert run_info(run_dir).status == "running"
        con = open_run(run_dir)  # held open across the writer's death
        assert con.execute("SELECT status FROM run").fetchone()[0] == "running"
    finally:
        proc.kill()
        proc.wait(PATIENCE)
    assert run_info(run_dir).status == "crashed"
    assert con.execute("SELECT status, ended_at FROM run").fetchone() == ("crashed", None)
