"""What the store records: exactly the episodes asked for, with t_end and seed; leftovers of a killed
writer or a failed seal cleaned up; `tracelab check [--repair]` finds and quarantines damaged parts."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from patience import PATIENCE
from store_helpers import WALK_EPISODES, write_walk_run

from tracelab.cli import main
from tracelab.store import layout
from tracelab.store.parts import read_manifest
from tracelab.store.reader import open_run
from tracelab.store.seal import seal_run

PROC = Path(__file__).resolve().parent / "store_proc.py"


def test_play_stores_exactly_the_episodes_asked_for(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "play"
    assert main(["play", "--scenario", "base", "--episodes", "5", "--seed", "9",
                 "--run", str(run)]) == 0
    assert "played 5 episodes" in capsys.readouterr().out
    con = open_run(run)
    rows = con.execute("SELECT episode, ended, outcome, steps, t_start, t_end, seed FROM episodes "
                       "ORDER BY episode").fetchall()
    assert [r[0] for r in rows] == [0, 1, 2, 3, 4]
    for episode, ended, outcome, steps, t_start, t_end, seed in rows:
        assert ended and outcome in ("win", "loss", "terminated", "truncated"), rows
        assert (t_start, t_end, seed) == (0, steps, 9)
    last_t = dict(con.execute("SELECT episode, max(t) FROM changes GROUP BY 1").fetchall())
    last_step = dict(con.execute("SELECT episode, max(step) FROM steps GROUP BY 1").fetchall())
    assert last_t == last_step == {r[0]: r[3] for r in rows}  # t_end = steps = the last step's t


def fingerprint_rows(run: Path) -> tuple[int, int]:
    con = open_run(run)
    try:
        return con.execute("SELECT (SELECT count(*) FROM raw.changes), (SELECT count(*) FROM raw.steps)"
                           ).fetchone()
    finally:
        con.close()


def killed_run(run_dir: Path, commits: int = 6) -> Path:
    """A run whose writer (tests/store_proc.py crash) was killed with SIGKILL after `commits` episodes."""
    proc = subprocess.Popen([sys.executable, str(PROC), "crash", str(run_dir)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        seen = 0
        deadline = time.monotonic() + PATIENCE
        while seen < commits:
            line = proc.stdout.readline()
            assert line and time.monotonic() < deadline, proc.stderr.read()
            seen += line.startswith("committed")
        proc.send_signal(signal.SIGKILL)
        proc.wait(PATIENCE)
    finally:
        proc.kill()
    return run_dir


def plant_leftovers(run: Path) -> list[Path]:
    """Temp files as a writer killed mid-write and a seal that failed would leave them."""
    files = [run / "parts" / "changes" / ".00000999.parquet.tmp-4242", run / ".meta.json.tmp-4242",
             run / ".run.duckdb.tmp-4243", run / ".run.duckdb.tmp-4243.wal"]
    for f in files:
        f.write_bytes(b"partial")
    return files


def parquet_files(run: Path) -> set[Path]:
    return {p.resolve() for p in (run / "parts").glob("*/*.parquet")}


def test_check_repair_cleans_up_after_a_killed_writer(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = killed_run(tmp_path / "killed")
    leftovers = plant_leftovers(run)
    listed = {p for files in read_manifest(run).values() for p in files}
    unlisted = parquet_files(run) - listed
    assert unlisted, "the crash writer compacts: a kill leaves parts the manifest no longer lists"
    before = fingerprint_rows(run)
    assert main(["check", str(run), "--repair"]) == 0
    out = capsys.readouterr().out
    assert f"removed {len(leftovers)} temp file(s)" in out and out.rstrip().endswith("ok")
    assert parquet_files(run) == listed and not any(f.exists() for f in leftovers)
    assert fingerprint_rows(run) == before


def test_seal_removes_leftovers_and_a_failed_seals_temp_file(tmp_path: Path) -> None:
    run = killed_run(tmp_path / "killed", commits=3)
    leftovers = plant_leftovers(run)
    listed = {p for files in read_manifest(run).values() for p in files}
    before = fingerprint_rows(run)
    seal_run(run, keep_parts=True)
    assert not any(f.exists() for f in leftovers)
    assert parquet_files(run) == listed
    assert fingerprint_rows(run) == before
    assert sorted(p.name for p in run.iterdir()) == ["meta.json", "parts", "run.duckdb", "writer.lock"]


def damage(path: Path) -> None:
    """Scramble bytes of a Parquet file's first data pages, keeping its footer."""
    data = bytearray(path.read_bytes())
    for i in range(64, 128):
        data[i] ^= 0x5A
    path.write_bytes(bytes(data))


def test_check_finds_and_quarantines_a_damaged_part(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = write_walk_run(tmp_path / "walk")
    assert main(["check", str(run)]) == 0
    assert capsys.readouterr().out.rstrip().endswith("ok")
    part = max((run / "parts" / "changes").glob("*.parquet"), key=lambda p: p.stat().st_size)
    damage(part)
    for metrics_part in (run / "parts" / "metrics").glob("*.parquet"):  # every part of a table
        damage(metrics_part)
    assert main(["check", str(run)]) == 1
    out = capsys.readouterr().out
    relative = part.relative_to(run)
    held = ", ".join(map(str, WALK_EPISODES))
    assert f"damaged: {relative} (changes; it held episodes {held}" in out or \
        f"damaged: {relative} (changes; it held episodes {min(WALK_EPISODES)} to {max(WALK_EPISODES)}" in out
    assert f"tracelab check {run} --repair" in out
    assert main(["check", str(run), "--repair"]) == 0
    out = capsys.readouterr().out
    assert "quarantined" in out and (run / "quarantine" / "changes" / part.name).exists()
    assert part.resolve() not in {p for files in read_manifest(run).values() for p in files}
    con = open_run(run)
    assert con.execute("SELECT count(*) FROM metrics").fetchone() == (0,)  # an empty part keeps its schema
    assert con.execute("SELECT count(*) FROM episodes").fetchone() == (3,)
    con.close()
    assert main(["check", str(run)]) == 0
    assert json.loads((run / "parts" / "manifest.json").read_text())["format"] == "tracelab-parts/1"


def test_check_reads_a_sealed_run(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = write_walk_run(tmp_path / "walk")
    seal_run(run)
    assert main(["check", str(run)]) == 0
    assert "sealed file" in capsys.readouterr().out
    assert layout.sealed_path(run).exists()


def test_repair_is_refused_while_a_writer_holds_the_run(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "busy"
    proc = subprocess.Popen([sys.executable, str(PROC), "idle", str(run)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "wrote"
        assert main(["check", str(run), "--repair"]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "still being written" in err[0] and "before repairing it" in err[0]
        assert main(["check", str(run)]) == 0  # checking alone reads, and needs no lock
    finally:
        proc.kill()
        proc.wait(PATIENCE)
