"""Runs from strangers, round two (issues 37 and 43): a run folder's name is a name, never a pattern;
nothing a command writes into a run goes through a link; strings from a run reach the terminal with
their control characters escaped; a repair is all or nothing; a closing hint never fails a command."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest
from store_helpers import TRACELAB, tampered_copy, write_walk_run

from tracelab.cli import main
from tracelab.store import TraceWriter
from tracelab.store.seal import seal_run


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_walk_run(tmp_path_factory.mktemp("strangers-runs") / "walk")


def json_rows(argv: list[str], capsys: pytest.CaptureFixture) -> list[dict]:
    assert main([*argv, "--format", "json"]) == 0
    return json.loads(capsys.readouterr().out)


# ---- 43.2: a run folder's name is read as a name ----------------------------------------------------------

@pytest.mark.parametrize("name", ["r*", "r?z", "r[!a]z", "r{zz,a}"])
@pytest.mark.parametrize("sealed", [False, True], ids=["live", "sealed"])
def test_a_run_named_like_a_pattern_reads_only_its_own_parts(walk: Path, tmp_path: Path, name: str,
                                                            sealed: bool, capsys: pytest.CaptureFixture) -> None:
    """`r*` beside `rzz` (and the other glob syntaxes beside a run they would match): each run reads
    its own three episodes, alone or as a folder of runs, live or sealed."""
    folder = tmp_path / "runs"
    folder.mkdir()
    for n in (name, "rzz", "rzzz"):
        shutil.copytree(walk, folder / n)
    if sealed:  # DuckDB cannot create a file under a '?': sealed elsewhere, then moved in
        shutil.rmtree(folder / name)
        shutil.copytree(walk, tmp_path / "plain")
        seal_run(tmp_path / "plain")
        (tmp_path / "plain").rename(folder / name)
    alone = json_rows(["sql", str(folder / name), "SELECT episode FROM episodes ORDER BY episode"], capsys)
    assert [r["episode"] for r in alone] == [10, 11, 12]
    several = json_rows(["sql", str(folder), "SELECT run, count(*) AS n FROM episodes GROUP BY run ORDER BY run"],
                        capsys)
    assert {r["run"]: r["n"] for r in several} == {name: 3, "rzz": 3, "rzzz": 3}


def test_a_fact_table_named_like_a_pattern_is_that_one_file(tmp_path: Path) -> None:
    from tracelab.engine.facttable import load_fact_table
    (tmp_path / "f*.csv").write_text("atom\nred(a)\n")
    (tmp_path / "fzz.csv").write_text("atom\nblue(b)\nblue(c)\n")
    graph = load_fact_table(tmp_path / "f*.csv")
    assert graph.n_facts == 1


@pytest.mark.parametrize("name", ["r*", "r[z]z"])
def test_seal_reads_only_the_parts_of_a_run_named_like_a_pattern(walk: Path, tmp_path: Path, name: str,
                                                                 capsys: pytest.CaptureFixture) -> None:
    for n in (name, "rzz"):
        shutil.copytree(walk, tmp_path / n)
    seal_run(tmp_path / name)
    rows = json_rows(["sql", str(tmp_path / name), "SELECT count(*) AS n FROM episodes"], capsys)
    assert rows == [{"n": 3}]


def test_seal_refuses_a_path_with_a_question_mark_in_one_line(walk: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture) -> None:
    shutil.copytree(walk, tmp_path / "r?z")
    assert main(["seal", str(tmp_path / "r?z")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "'?'" in err and "Traceback" not in err


# ---- 37.7: a run's strings reach the terminal with their control characters escaped -------------------

# a title (OSC 0 ... BEL), a clear screen (CSI 2J), an OSC-8 link, an 8-bit CSI (U+009B) and a bidi
# override: none of them may reach the terminal raw
PAYLOAD = ("\x1b]0;owned\x07\x1b[2J\x1b]8;;https://evil.example/\x1b\\click\x1b]8;;\x1b\\"
           "\u009b31m\u202egnp.exe")
MARKUP = "[bold]B[/bold][@click=app.quit]Q[/]"  # must show as these characters in the TUI
RAW_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")


def assert_no_raw_controls(text: str) -> None:
    found = RAW_CONTROL.findall(text)
    assert not found, f"raw control characters reached the terminal: {found!r}"


@pytest.fixture(scope="module")
def planted(walk: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with the walk run twice: `live`, whose meta.json command and host carry the payload, and
    `sealed`, whose raw.run command and outcomes were set to it with plain DuckDB."""
    folder = tmp_path_factory.mktemp("planted")
    live = shutil.copytree(walk, folder / "live")
    doc = json.loads((live / "meta.json").read_text())
    doc.update(command=PAYLOAD, host=PAYLOAD, scenario=PAYLOAD)
    (live / "meta.json").write_text(json.dumps(doc))
    sealed = shutil.copytree(walk, folder / "plain")
    seal_run(sealed)
    quoted = PAYLOAD.replace("'", "''")
    tampered_copy(sealed, folder / "sealed", f"UPDATE raw.run SET command = '{quoted}', host = '{quoted}'",
                  f"UPDATE raw.episode_end SET outcome = '{quoted}'",
                  f"UPDATE raw.rules SET name = '{MARKUP}' || name || '{quoted}'")
    shutil.rmtree(sealed)
    doc = json.loads((folder / "sealed" / "meta.json").read_text())
    doc.update(command=PAYLOAD, host=PAYLOAD)
    (folder / "sealed" / "meta.json").write_text(json.dumps(doc))
    return folder


def tracelab(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*TRACELAB, *argv], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("argv", [
    ["show", "{planted}/live"],
    ["show", "{planted}/sealed", "--json"],
    ["sql", "{planted}/live", "SELECT command, host FROM run"],
    ["sql", "{planted}/sealed", "SELECT outcome FROM episodes"],
    ["sql", "{planted}/sealed", "SELECT command FROM run", "--format", "csv"],
    ["runs", "{planted}"],
], ids=["show-live", "show-json-sealed", "sql-command-live", "sql-outcome-sealed", "sql-csv-sealed", "runs"])
def test_the_cli_prints_a_runs_strings_escaped(planted: Path, argv: list[str]) -> None:
    done = tracelab(*(a.format(planted=planted) for a in argv))
    assert done.returncode == 0, done.stderr
    assert_no_raw_controls(done.stdout + done.stderr)
    assert re.search(r"\\(x1b|u001b)\]0;owned", done.stdout), done.stdout  # shown, as text


def test_an_error_quoting_a_runs_string_is_escaped(planted: Path) -> None:
    done = tracelab("sql", str(planted / "sealed"), "SELECT error(command) FROM run")
    assert done.returncode == 1 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert_no_raw_controls(done.stderr)
    assert "\\x1b]0;owned" in done.stderr


def test_the_tui_shows_a_runs_strings_escaped_and_never_as_markup(planted: Path) -> None:
    """The run's command in the title, its outcomes in Episodes and its rule names in Rules: shown as
    text (escapes written out, markup as its characters), never sent to the terminal raw."""
    from tui_helpers import LazyTable, episodes_ready, loaded, run_app, shown_once

    async def body(app: Any, pilot: Any) -> None:
        await episodes_ready(app, pilot)
        screens = [await shown_once(app, pilot, lambda text: "owned" in text)]
        await pilot.press("4")
        await wait_until(pilot, lambda: app.screen.panes["rules"].is_attached)
        table = app.screen.panes["rules"].query_one(LazyTable)
        await wait_until(pilot, lambda: loaded(table) and table.count > 0)
        screens.append(await shown_once(app, pilot, lambda text: "[bold]" in text))
        for text in screens:
            assert_no_raw_controls(text)
            assert "\\x1b]0;owned" in text, text
        assert "[bold]B[/bold]" in screens[1], screens[1]
    run_app([planted / "sealed"], body, size=(160, 40))


async def wait_until(pilot: Any, done: Any) -> None:
    from tui_helpers import wait_for
    await wait_for(pilot, done, timeout=120)


# ---- a reasoning run from a stranger, replayed -----------------------------------------------------------

@pytest.fixture(scope="module")
def reasoning(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """test_replay_graph's run (a graph with positions, infected spreading along links), sealed."""
    from test_replay_graph import record
    run = record(tmp_path_factory.mktemp("reasoning"), positions=True)
    seal_run(run)
    return run


def test_the_replays_text_holds_no_raw_control_characters(reasoning: Path, tmp_path: Path) -> None:
    """Rule and node names planted with escapes: the rule log (text and level) and the why documents
    of the recording hold them escaped."""
    from test_replay import read_rrd
    quoted = PAYLOAD.replace("'", "''")
    run = tampered_copy(reasoning, tmp_path / "run", f"UPDATE raw.rules SET name = name || '{quoted}'",
                        f"UPDATE raw.nodes SET name = name || '{quoted}' WHERE name <> 'd'")
    assert main(["replay", str(run), "--save", str(tmp_path / "r.rrd"), "--why", "infected(d)"]) == 0
    (recording,) = read_rrd(tmp_path / "r.rrd").values()
    texts = [*(r["TextLog:text"][0] + r["TextLog:level"][0] for r in recording["/rules/log"]),
             *(r["TextDocument:text"][0] for r in recording["/why"])]
    assert texts and any("\\x1b]0;owned" in t for t in texts)
    for text in texts:
        assert_no_raw_controls(text)


@pytest.mark.parametrize("tamper", [
    "UPDATE raw.edges SET source = 1000 WHERE source = 0",
    "UPDATE raw.edges SET target = -5",
    "UPDATE raw.atoms SET arg0 = 777 WHERE arg1 < 0 AND arg0 >= 0",   # a node's x/y, colour atoms
    "UPDATE raw.atoms SET arg1 = 99 WHERE arg1 >= 0",                 # the edges drawn from binary atoms
], ids=["edge-source", "edge-target", "unary-atom-node", "binary-atom-node"])
def test_a_replay_of_node_ids_out_of_range_is_one_line(reasoning: Path, tmp_path: Path, tamper: str,
                                                        capsys: pytest.CaptureFixture) -> None:
    run = tampered_copy(reasoning, tmp_path / "run", tamper)
    assert main(["replay", str(run), "--save", str(tmp_path / "r.rrd")]) == 1
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "out of range" in err


# ---- 43.1: nothing a command writes into a run goes through a link -------------------------------------

def tree_digest(folder: Path) -> dict[str, str]:
    import hashlib
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(folder.rglob("*"))}


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from train_helpers import tiny_training_run
    return tiny_training_run(tmp_path_factory.mktemp("trained") / "run")


@pytest.mark.parametrize("linked", ["policy", "policy-best", "checkpoint"])
def test_train_resume_never_writes_through_a_link_in_the_run(trained: Path, tmp_path: Path, linked: str,
                                                            capsys: pytest.CaptureFixture) -> None:
    """RUN/policy (policy-best, checkpoint) a link to a folder outside the run: the resume refuses it in
    one line and the folder it leads to is as it was."""
    run = shutil.copytree(trained, tmp_path / "run")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("mine\n")
    shutil.rmtree(run / linked)
    (run / linked).symlink_to(outside, target_is_directory=True)
    before = tree_digest(outside)
    from train_helpers import walk_argv
    status = main(["train", "--resume", str(run), *walk_argv(), "--steps", "400"])
    err = capsys.readouterr().err
    assert tree_digest(outside) == before
    errors = [line for line in err.splitlines() if line.startswith("tracelab: error:")]
    assert status == 1 and len(errors) == 1 and "symbolic link" in errors[0] and "Traceback" not in err, err


# ---- 43.5: a closing hint never fails a command that did its job ----------------------------------------

def test_play_env_succeeds_when_its_hint_query_runs_out_of_memory(tmp_path: Path) -> None:
    """A query memory too small for the hints' reads (what a 4M-grounding run meets at the defaults):
    the run is written, the command exits 0 and says what to open."""
    import os
    run = tmp_path / "run"
    done = subprocess.run([*TRACELAB, "play", "--env", "tracelab/FrozenLake-v1", "--env-arg", "map_name=8x8",
                           "--env-arg", "is_slippery=false", "--episodes", "12", "--seed", "2", "--run", str(run)],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TRACELAB_QUERY_MEMORY": "4M"})
    assert done.returncode == 0 and "error" not in done.stderr, done.stderr
    assert f"run written to {run}/" in done.stdout and f"tracelab tui {run}" in done.stdout
    assert json.loads((run / "meta.json").read_text())["status"] == "finished"


# ---- 43.6: a repair is all or nothing ---------------------------------------------------------------------

# `tracelab check --repair RUN` with files limited to a few bytes (RLIMIT_FSIZE: writing past it fails with
# EFBIG once SIGXFSZ is ignored), as a full disk fails the repair's writes: a real error of the real code
REPAIR_WITHOUT_ROOM = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (64, 64))
from tracelab.cli import main
sys.exit(main(["check", "--repair", sys.argv[1]]))
"""


@pytest.mark.parametrize("damaged", ["changes", "edges"])  # edges: its only part, so an empty one is written
def test_a_repair_that_cannot_write_leaves_the_run_as_it_was(walk: Path, tmp_path: Path, damaged: str,
                                                             capsys: pytest.CaptureFixture) -> None:
    import sys
    run = shutil.copytree(walk, tmp_path / "run")
    part = sorted((run / "parts" / damaged).glob("*.parquet"))[-1]
    part.write_bytes(part.read_bytes()[: len(part.read_bytes()) // 2])   # torn: its footer is gone
    before = tree_digest(run)
    done = subprocess.run([sys.executable, "-c", REPAIR_WITHOUT_ROOM, str(run)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 1 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "repair not made" in done.stderr
    assert {k: v for k, v in tree_digest(run).items() if k != "writer.lock"} == \
        {k: v for k, v in before.items() if k != "writer.lock"}
    assert main(["check", "--repair", str(run)]) == 0    # room again: the repair is made
    assert (run / "quarantine" / damaged / part.name).is_file() and not part.exists()
    assert main(["check", str(run)]) == 0
    capsys.readouterr()
    assert json_rows(["sql", str(run), "SELECT count(*) AS n FROM episodes"], capsys) == [{"n": 3}]


# ---- 37.5: a run never writes what its own readers refuse; the program goes in as a part ------------------

def test_a_spec_with_a_big_rule_file_makes_a_run_that_every_reader_reads(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture) -> None:
    """FrozenLake's spec with 20 MiB of comments in its rule file (under the rule-file cap and the parse
    memory's estimate, over what meta.json's readers accept): the texts go in the run's `sources` table,
    meta.json stays a few KB, and `show`, `sql` and `runs` read the run, live and sealed."""
    from tracelab.engine.safe_files import JSON_CAP
    from tracelab.envs.declared.toytext import spec_path
    world = tmp_path / "world"
    world.mkdir()
    shutil.copy(spec_path("frozen_lake.toml"), world)
    rules = spec_path("frozen_lake.toml").with_name("frozen_lake.rules").read_text()
    (world / "frozen_lake.rules").write_text(rules + ("# " + "x" * 1021 + "\n") * (20 << 10))
    size = (world / "frozen_lake.rules").stat().st_size
    assert size > JSON_CAP  # on main, the text landed in meta.json, which every reader then refused
    run = tmp_path / "runs" / "big"
    assert main(["play", "--env", str(world / "frozen_lake.toml"), "--episodes", "2", "--seed", "1",
                 "--run", str(run)]) == 0
    capsys.readouterr()
    assert (run / "meta.json").stat().st_size < 16 << 10
    config = json.loads((run / "meta.json").read_text())["config"]
    assert config["sources"][1]["bytes"] == size and len(config["sources"][1]["sha256"]) == 64
    for sealed in (False, True):
        if sealed:
            seal_run(run)
        assert main(["show", str(run)]) == 0
        shown = capsys.readouterr().out
        assert f"\nspec      {world / 'frozen_lake.toml'}\n" in shown and 'rules = ["frozen_lake.rules"]' in shown
        assert "xxxx" not in shown  # the rule file's text is not printed (`sql` reads it)
        assert json_rows(["sql", str(run), "SELECT role, bytes, length(text) AS n, text LIKE '%frozen%' AS ours "
                          "FROM raw.sources"], capsys) == [
            {"role": "spec", "bytes": (world / "frozen_lake.toml").stat().st_size,
             "n": len((world / "frozen_lake.toml").read_text()), "ours": True},
            {"role": "rules", "bytes": size, "n": size, "ours": True}]
        listed = json_rows(["runs", str(tmp_path / "runs")], capsys)
        assert [(r["name"], r["status"], r["episodes"]) for r in listed] == [("big", "finished", 2)]


@pytest.mark.parametrize("sealed", [False, True], ids=["live", "sealed"])
def test_an_older_run_with_its_program_in_meta_json_still_shows_it(tmp_path: Path, sealed: bool,
                                                                   capsys: pytest.CaptureFixture) -> None:
    """A run written before the `sources` table: its spec's and rule files' texts in meta.json's config
    (`spec`, `rule_texts`), no `sources` in its manifest or sealed file. `show` prints its spec."""
    run = tmp_path / "old"
    spec = '[env]\nrules = ["old.rules"]\n\n[board]\nrows = ["S.G"]\n'
    with TraceWriter(run, {"command": "tracelab play --env old.toml", "config": {
            "spec": spec, "rule_texts": {"old.rules": "a: b(x) <-1 c(x)\n"}, "spec_path": "old.toml",
            "declared_facts": {"actions": ["pressed"], "draws": {}}}}):
        pass
    manifest = json.loads((run / "parts" / "manifest.json").read_text())
    del manifest["tables"]["sources"]
    (run / "parts" / "manifest.json").write_text(json.dumps(manifest))
    shutil.rmtree(run / "parts" / "sources", ignore_errors=True)
    if sealed:
        seal_run(run)
        run = tampered_copy(run, tmp_path / "old-sealed", "DROP TABLE raw.sources")
    assert main(["show", str(run)]) == 0
    shown = capsys.readouterr().out
    assert "\nspec      old.toml\n  [env]\n  rules = [\"old.rules\"]\n" in shown and '  rows = ["S.G"]' in shown
    assert json_rows(["sql", str(run), "SELECT count(*) AS n FROM raw.sources"], capsys) == [{"n": 0}]


def test_a_run_whose_meta_json_its_readers_would_refuse_is_never_written(tmp_path: Path) -> None:
    """meta.json is written only as big as read_meta accepts (META_CAP): past it the writer refuses with
    one line, before it creates anything."""
    from tracelab.engine.safe_files import FileRefused
    from tracelab.store.meta import META_CAP
    run = tmp_path / "run"
    with pytest.raises(FileRefused, match=r"meta.json: run metadata of 8.* is over the 8 MiB its readers accept"):
        TraceWriter(run, {"config": {"note": "x" * META_CAP}})
    assert not run.exists()
    with TraceWriter(run, {"config": {"note": "x" * (META_CAP - 4096)}}):  # just under: written and read
        pass
    assert main(["show", str(run)]) == 0


@pytest.mark.parametrize("kind", ["fifo", "file"])
def test_runs_of_something_that_is_not_a_folder_is_one_line_and_fails(tmp_path: Path, kind: str,
                                                                      capsys: pytest.CaptureFixture) -> None:
    """`tracelab runs NAME` where NAME is a FIFO or a file: neither a folder of runs nor a run, so it is
    an error (it listed nothing and exited 0), and the FIFO is never opened (a read would block)."""
    path = tmp_path / kind
    os.mkfifo(path) if kind == "fifo" else path.write_text("not a run")
    assert main(["runs", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a directory or run" in err and kind in err, err


def test_the_replays_markdown_shows_a_runs_strings_as_text() -> None:
    """A why-document's atom, rule and outcome from a run are text, never markup: an image or a link in
    an atom's name is escaped, and a tree holding ``` stays inside its code block."""
    from tracelab.viewers.replay.markdown_text import code_block, literal
    assert literal("p(![x](https://example.org/a.png))") == r"p(\!\[x\](https://example.org/a.png))"
    assert literal("<img src=x>") == r"\<img src=x\>" and literal("alive(red-agent-1)") == "alive(red-agent-1)"
    fence, body, end = code_block("a ``` b ```` c")
    assert fence == "`````text" and end == "`````" and body == "a ``` b ```` c"
