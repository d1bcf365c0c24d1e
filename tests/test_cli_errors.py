"""Bad invocations of the `tracelab` command, each in its own process: a user error is exactly one line
`tracelab: error: ...` on stderr and exit status 1, a usage error is argparse's message and status 2, and
nothing prints a traceback. The read commands use the sample runs (read only)."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tracelab.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
RUN = str(ROOT / "sample_runs" / "base")  # 3 episodes; episode 0 ends at t=74
CLI = [sys.executable, "-m", "tracelab"]


def tracelab(*args: str | bytes, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, cwd=cwd, timeout=timeout, check=False,
                          env={**os.environ, "COLUMNS": "100"})


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Rule files and folders the bad invocations point at."""
    d = tmp_path_factory.mktemp("bad")
    (d / "latin1.rules").write_bytes(b"agent(a)\nname(b, caf\xe9)\n")
    (d / "osc.rules").write_text("a(x)\np(x)\n"
                                 "on: p(x):[1,1] <-0 a(x), p(x):[0,0] {override}\n"
                                 "off: p(x):[0,0] <-0 a(x), p(x):[1,1] {override}\n")
    (d / "abort.rules").write_text("%inconsistency abort\na(x)\np(x):[0.2,0.8]\n"
                                   "low: p(x):[0,0] <-1 a(x)\nhigh: p(x) <-1 a(x)\n")
    (d / "delay.rules").write_text("a(x)\nlate: p(x) <-99999999999999999999 a(x)\n")
    (d / "wide.rules").write_text("a(x)\nwide: p(X) <-0 " + ", ".join(f"a(X{i})" for i in range(200)) + "\n")
    (d / "crowd.toml").write_text('name = "crowd"\nwidth = 8\nheight = 8\nred_base = [7, 0]\n'
                                  'blue_base = [0, 7]\nagents_per_team = 200\n')
    (d / "latin1.toml").write_bytes(b'name = "caf\xe9"\n')
    (d / "old-run").mkdir()
    (d / "old-run" / "meta.json").write_text("{}")
    (d / "a-file").write_text("not a directory")
    (d / "busy").mkdir()
    (d / "busy" / "notes.txt").write_text("someone else's")
    return d


# (arguments, what stderr's one line must contain); {d} is the folder of `files`
USER_ERRORS = [
    # play --run
    (["play", "--run", "{d}/old-run"], "already holds a run"),
    (["play", "--run", "{d}/a-file"], "is a file, not a directory"),
    (["play", "--run", "/proc/x/run"], "cannot create the run directory /proc/x/run"),
    (["play", "--run", "{d}/busy"], "holds other files (notes.txt)"),
    (["play", "--scenario", "{d}/crowd.toml"], "200 agents a team do not fit the 8x8 map"),
    (["play", "--scenario", "{d}/none.toml"], "none.toml: cannot read"),
    (["play", "--scenario", "{d}/latin1.toml"], "latin1.toml: not UTF-8 text: byte 0xe9 at byte offset 11"),
    # reason
    (["reason", "{d}/latin1.rules", "--steps", "1"], "latin1.rules:2:12: the file is not UTF-8 text: byte 0xe9"),
    (["reason", "{d}/osc.rules", "--steps", "2"], "no fixpoint at t=0"),
    (["reason", "{d}/abort.rules", "--steps", "3"], "the bound before was [0.2,0.8], from fact"),
    (["reason", "{d}/delay.rules", "--steps", "1"], ("delay.rules:2:12: the delay 99999999999999999999 is too "
                                                     "large: a delay is at most 1000000000")),
    (["reason", "{d}/wide.rules", "--steps", "1"], ("wide.rules:2:1: rule 'wide' has 200 binding body clauses; "
                                                    "the engine allows at most 127")),
    (["reason", "{d}/missing.rules", "--steps", "1"], "missing.rules: No such file or directory"),
    # reading runs
    (["sql", RUN, b"SELECT 'caf\xe9'"], "the SQL query is not UTF-8 text: byte 0xe9 at offset 11"),
    (["sql", RUN, "SELECT nope FROM changes"], "(at line 1, column 8 of the query)"),
    (["sql", RUN, "SELECT 1", "--format", "parquet"], "--format parquet needs --output FILE"),
    (["sql", "{d}/no-such-run", "SELECT 1"], "no run"),
    (["why", RUN, "atLoc(red-agent-1,c1_1)", "-e", "0", "--at", "9999"],
     "--at 9999 is past the end of episode 0: its last timestep is t=74"),
    (["why-not", RUN, "-e", "0", "--rule", "m_up", "--at", "500"],
     "--at 500 is past the end of episode 0: its last timestep is t=74"),
    (["why", RUN, "~alive(red-agent-1)", "-e", "0"], "not a complement: ask `why 'alive(red-agent-1)'`"),
    (["trace", RUN, "-e", "0", "--from", "10", "--to", "2"], "--from 10 is after --to 2"),
    (["trace", RUN, "-e", "0", "--label", "nosuch"], "no label 'nosuch' in this run; its labels: "),
    (["trace", RUN, "-e", "77"], "episode 77 has no trace rows"),
    (["diff", RUN, "0", "0"], "two different episodes"),
    (["diff", f"{RUN}:0", f"{RUN}:x"], "expected an episode number, got 'x'"),
    (["diff", RUN, "0"], "cannot read"),
]

USAGE_ERRORS = [
    (["sql", RUN, "SELECT 1", "--offset", "-5"], "argument --offset: must be 0 or more, got -5"),
    (["play", "--seed", "-1"], "argument --seed: must be 0 or more, got -1"),
    (["trace", RUN, "-e", "0", "--limit", "-5"], "argument --limit: must be 0 or more, got -5"),
    (["reason", "x.rules", "--steps", "-1"], "argument --steps: must be at least 1, got -1"),
    (["play", "--episodes", "lots"], "argument --episodes: expected an integer, got 'lots'"),
    (["why", RUN, "alive(red-agent-1)", "-e", "0", "--at", "-3"], "argument --at: must be 0 or more"),
    (["nosuch"], "invalid choice"),
]


COMPILE_NOTICE = "tracelab: compiling the engine (first run only"


def _args(args: list, d: Path) -> list:
    return [a.replace("{d}", str(d)) if isinstance(a, str) else a for a in args]


@pytest.mark.parametrize("args, needle", USER_ERRORS, ids=[" ".join(map(str, a))[:60] for a, _ in USER_ERRORS])
def test_a_user_error_is_one_line_and_exit_1(files: Path, args: list, needle: str) -> None:
    p = tracelab(*_args(args, files))
    err = p.stderr.decode()
    assert p.returncode == 1, err
    assert "Traceback" not in err
    # a cold numba cache (a fresh clone) adds the compile notice before the engine's first run
    lines = [ln for ln in err.splitlines() if not ln.startswith(COMPILE_NOTICE)]
    assert len(lines) == 1 and lines[0].startswith("tracelab: error: "), err
    assert needle in lines[0], err


@pytest.mark.parametrize("args, needle", USAGE_ERRORS, ids=[" ".join(a)[:60] for a, _ in USAGE_ERRORS])
def test_a_usage_error_is_argparse_and_exit_2(args: list, needle: str) -> None:
    p = tracelab(*args)
    err = p.stderr.decode()
    assert p.returncode == 2 and "Traceback" not in err, err
    assert needle in err.splitlines()[-1], err


def star_rules(path: Path, leaves: int = 3000) -> Path:
    """Reachability from a hub to `leaves` nodes, whose `reason --json` output (~1 MB) outgrows a pipe's
    buffer, so the command must still be writing when the reader goes away (a small output could all be
    written, and the command exit 0, before the reader closes)."""
    facts = "\n".join(f"edge(hub, n{i}) static" for i in range(leaves))
    path.write_text(f"{facts}\nreach(hub)\nspread: reach(Y) <-0 reach(X), edge(X, Y)\n")
    return path


@pytest.mark.parametrize("args", [
    ["sql", RUN, "SELECT * FROM changes"],
    ["trace", RUN, "-e", "0", "--format", "csv"],
    ["reason", "STAR", "--steps", "2", "--json"],
])
def test_a_closed_pipe_ends_quietly(args: list[str], tmp_path: Path) -> None:
    args = [str(star_rules(tmp_path / "star.rules")) if a == "STAR" else a for a in args]
    p = subprocess.Popen([*CLI, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout.readline()  # `| head -1`
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=300) == 141 and err == ""


def _an_episode_ended(run: Path) -> bool:
    """A part of episode_end with rows (the writer may list a part before any game ended)."""
    import pyarrow.parquet as pq
    for part in (run / "parts" / "episode_end").glob("*.parquet"):
        try:
            if pq.read_metadata(part).num_rows:
                return True
        except (OSError, ValueError):  # being renamed or retired while we look
            continue
    return False


def test_a_second_play_into_the_same_run_is_refused_and_ctrl_c_says_what_was_kept(tmp_path: Path) -> None:
    run = tmp_path / "shared"
    first = subprocess.Popen([*CLI, "play", "--scenario", "base", "--episodes", "100000", "--run", str(run)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 300
        while not (run / "meta.json").exists():  # the writer opens the run before the long build
            assert first.poll() is None and time.monotonic() < deadline, first.stderr.read().decode()
            time.sleep(0.1)
        second = tracelab("play", "--scenario", "base", "--episodes", "1", "--run", str(run))
        err = second.stderr.decode()
        assert second.returncode == 1 and err.count("\n") == 1, err
        assert err.startswith(f"tracelab: error: --run {run} already holds a run"), err
        # Ctrl-C once games are being played: a cold numba cache compiles for a minute or more first
        while not _an_episode_ended(run):
            assert first.poll() is None and time.monotonic() < deadline + 300, first.stderr.read().decode()
            time.sleep(0.2)
        first.send_signal(signal.SIGINT)
        code = first.wait(timeout=120)
        err = first.stderr.read().decode()
        assert code == 130, err
        assert "stopping after this step" in err, err  # the first Ctrl-C stops between two steps
        last = err.splitlines()[-1]
        assert re.fullmatch(rf"tracelab: interrupted: {re.escape(str(run))} keeps [1-9]\d* finished episode\(s\) "
                            r"and the trace so far", last), last
        assert '"status": "interrupted"' in (run / "meta.json").read_text()
    finally:
        if first.poll() is None:
            first.kill()
            first.wait(timeout=120)


def test_version_and_python_m() -> None:
    from tracelab import __version__
    p = tracelab("--version")
    assert p.returncode == 0 and p.stdout.decode().strip() == f"tracelab {__version__}"
    p = tracelab("--help")
    assert p.returncode == 0 and b"play" in p.stdout


def test_every_flag_of_every_command_has_help() -> None:
    import argparse

    def missing(parser: argparse.ArgumentParser, path: str) -> list[str]:
        out = []
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sub in a.choices.items():
                    out += missing(sub, f"{path} {name}")
            elif not a.help:
                out.append(f"{path} {'/'.join(a.option_strings) or a.dest}")
        return out

    assert missing(build_parser(), "tracelab") == []
