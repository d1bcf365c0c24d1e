"""`tracelab reason --run DIR`: any rule program recorded into a run of the trace store (tracelab/reasoning.py,
tracelab/store/reasoning.py), and every reading command on such a run (trace, why, why-not, sql, diff,
show, check, seal, runs), with real runs written by the CLI; the store knowing no game (the board decoder
lives in viewers/, a run declares its board or has none); old runs opening as before."""
from __future__ import annotations

import json
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
from store_helpers import run_rows as rows

from tracelab.cli import main

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "rules" / "examples"
PYREASON = Path(__file__).resolve().parent / "data" / "pyreason"
SAMPLES = ROOT / "sample_runs"

# a small graph in PyReason's way of bringing one: node and edge attributes are the facts
GRAPH = """<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
<key id="sick" for="node" attr.name="infected" attr.type="boolean"/>
<key id="mask" for="node" attr.name="masked" attr.type="boolean"/>
<key id="link" for="edge" attr.name="contact" attr.type="double"/>
<graph edgedefault="directed">
<node id="ann"><data key="sick">true</data></node>
<node id="bob"/><node id="cid"/><node id="dan"><data key="mask">true</data></node><node id="eve"/>
<edge source="ann" target="bob"><data key="link">1</data></edge>
<edge source="bob" target="cid"><data key="link">0.9</data></edge>
<edge source="cid" target="dan"><data key="link">1</data></edge>
<edge source="cid" target="eve"><data key="link">1</data></edge>
<edge source="eve" target="ann"/>
</graph></graphml>
"""
RULES = """%closed masked
spread: infected(Y) <-1 infected(X), contact(X,Y):[0.8,1], masked(Y):[0,0]
alarm:  alarm(X) <-! infected(X), contact(X,Y), masked(Y)
"""


def cli(capsys: pytest.CaptureFixture, *argv: str | Path) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    (d / "contacts.graphml").write_text(GRAPH)
    (d / "spread.rules").write_text(RULES)
    # eve wears a mask from t = 0 in the second world: one fact changed
    (d / "eve_masked.rules").write_text("masked(eve) static\n")
    (d / "seeds.csv").write_text('atom,episode\ninfected(cid),1\n"contact(dan,eve)",2\ninfected(eve),\n')
    (d / "abort.rules").write_text("%inconsistency abort\na(x)\np(x):[0.2,0.8]\n"
                                   "low: p(x):[0,0] <-1 a(x)\nhigh: p(x) <-1 a(x)\n")
    return {p.stem: p for p in d.iterdir()}


def record(capsys: pytest.CaptureFixture, run: Path, *argv: str | Path) -> str:
    code, out, err = cli(capsys, "reason", *argv, "--run", run)
    assert code == 0, err
    return out


@pytest.fixture(scope="module")
def run(inputs: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The contact program over the contact graph, recorded (module-scoped: read, never changed)."""
    path = tmp_path_factory.mktemp("runs") / "contacts"
    assert main(["reason", str(inputs["spread"]), "--graph", str(inputs["contacts"]), "--steps", "6",
                 "--run", str(path)]) == 0
    return path


# ---- recording ----------------------------------------------------------------------------------------

def test_reason_run_records_every_change_and_the_program_graph_and_command(
        run: Path, inputs: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "reason", inputs["spread"], "--graph", inputs["contacts"], "--steps", "6", "--json")
    printed = json.loads(out)
    assert code == 0
    stored = rows(run, "SELECT t, pass_no, atom, old_lower, old_upper, new_lower, new_upper, rule FROM changes "
                       "WHERE episode = 0 ORDER BY seq")
    # the same changes, in the same order, by the same causes, as `reason` prints them
    assert [(c["t"], c["pass"], c["atom"], *c["old"], *c["new"], c["cause"]) for c in printed["changes"]] == \
        [(t, p, a, *b, rule if not rule.startswith("fact:") else rule) for t, p, a, *b, rule in stored]
    assert ("infected(dan)",) not in rows(run, "SELECT atom FROM changes")  # dan's mask stopped it
    assert rows(run, "SELECT rule, bindings FROM firings WHERE head = 'infected(eve)'") == \
        [("spread", "Y=eve, X=cid")]
    assert rows(run, "SELECT name, literal, file FROM facts WHERE name = 'contact(bob,cid)'") == \
        [("contact(bob,cid)", "contact(bob,cid):[0.9,0.9]", str(inputs["contacts"]))]
    assert sorted(rows(run, "SELECT source, target FROM edges")) == [
        ("ann", "bob"), ("bob", "cid"), ("cid", "dan"), ("cid", "eve"), ("eve", "ann")]
    assert rows(run, "SELECT count(*) FROM atoms")[0][0] > 10 and rows(run, "SELECT count(*) FROM groundings")[0][0] > 0
    command, config, board = rows(run, "SELECT command, config, board FROM run")[0]
    config = json.loads(config)
    assert "--run" in command and board is None and config["steps"] == 6
    assert [s["role"] for s in config["sources"]] == ["rules", "graph"] and "text" not in config["sources"][0]
    assert config["sources"][0]["bytes"] == len(RULES.encode())
    assert rows(run, "SELECT role, text FROM raw.sources") == [("rules", RULES)]  # the program text itself
    # eve's infection at t=3 is the last change; two quiet steps (the spread's delay, plus one) converge
    assert rows(run, "SELECT episode, steps, t_end, outcome FROM episodes") == [(0, 6, 5, "converged")]


def test_reason_run_says_what_it_recorded_and_what_to_open(inputs: dict[str, Path], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    out = record(capsys, tmp_path / "r", inputs["spread"], "--graph", inputs["contacts"], "--steps", "2",
                 "--query", "infected(X)")
    lines = out.splitlines()
    assert lines[0] == "t=1 infected(X): 2 answers"  # queries are answered as without --run
    assert "recorded 1 episode (" in out and "episode 0 stopped after 2 steps" in out
    why = shlex.split(next(ln for ln in lines if "tracelab why" in ln).split("#")[0])
    assert cli(capsys, *why[1:])[0] == 0  # the suggested why command works as printed
    # --run and --no-trace contradict each other; a run directory is never reused
    for argv, msg in (([*map(str, (inputs["spread"], "--steps", "1", "--run", tmp_path / "x", "--no-trace"))],
                       "--run records the trace and --no-trace drops it"),
                      ([str(inputs["spread"]), "--steps", "1", "--run", str(tmp_path / "r")], "already holds a run")):
        code, _, err = cli(capsys, "reason", *argv)
        assert code == 1 and err.count("\n") == 1 and msg in err


def test_a_failed_reasoning_keeps_the_rows_up_to_its_error(inputs: dict[str, Path], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    code, _, err = cli(capsys, "reason", inputs["abort"], "--steps", "3", "--run", tmp_path / "r")
    assert code == 1 and err.startswith("tracelab: error: inconsistent bounds for p(x) at t=1")
    assert rows(tmp_path / "r", "SELECT status FROM run") == [("failed",)]
    assert rows(tmp_path / "r", "SELECT atom, t FROM changes ORDER BY seq") == [("a(x)", 0), ("p(x)", 0)]
    outcome, info = rows(tmp_path / "r", "SELECT outcome, end_info FROM episodes")[0]
    assert outcome == "failed" and json.loads(info)["error"].startswith("inconsistent bounds for p(x)")


def test_a_big_reasoning_is_handed_to_the_store_in_chunks(tmp_path: Path) -> None:
    """Rows leave the engine every HANDOVER_STEPS steps (and whenever TRACE_HANDOVER_ROWS wait), not at
    the end: a live reader sees them while the reasoning goes on."""
    from tracelab.engine import parse_program
    from tracelab.reasoning import EpisodeRun, ReasoningInputs, plan_episodes
    from tracelab.store import TraceWriter, open_run
    from tracelab.store.writer import HANDOVER_STEPS
    from tracelab.store.reasoning import ReasoningRecorder
    chain = "".join(f"next(n{i}, n{i + 1})\n" for i in range(300))
    program = parse_program("on(n0)\n" + chain + "walk: on(Y) <-1 on(X), next(X,Y)\n", "walk.rules")
    inputs = ReasoningInputs(program, None, None, 0, "tracelab")
    writer = TraceWriter(tmp_path / "walk", {"command": "test"})
    recorder = ReasoningRecorder(writer)
    episode = EpisodeRun(inputs, plan_episodes(inputs)[0], recorder=recorder)
    seen = []
    for t, _ in episode.steps(200):
        if t in (HANDOVER_STEPS - 2, HANDOVER_STEPS + 5, 3 * HANDOVER_STEPS + 5):
            writer.flush()
            seen.append((recorder.rows, episode.engine.trace_rows_waiting,
                         open_run(tmp_path / "walk").execute("SELECT count(*) FROM changes").fetchall()[0][0]))
    episode.finish()
    writer.close()
    # before the first chunk nothing has left the engine; after it, the rows so far are in the run
    assert seen[0][0] == 0 and seen[0][1] > 0
    assert seen[1][0] == seen[1][2] > 0 and seen[1][1] < seen[1][0]
    assert seen[2][2] > seen[1][2]
    assert open_run(tmp_path / "walk").execute("SELECT count(*), max(t) FROM changes").fetchall() == [(500, 199)]


# ---- episodes --------------------------------------------------------------------------------------

def test_a_fact_table_with_an_episode_column_gives_one_episode_each(inputs: dict[str, Path], tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture) -> None:
    argv = [inputs["spread"], "--graph", inputs["contacts"], "--facts-table", inputs["seeds"], "--steps", "4"]
    record(capsys, tmp_path / "r", *argv)
    r = tmp_path / "r"
    assert rows(r, "SELECT episode, begin_info FROM episodes ORDER BY 1") == [
        (1, '{"facts_episode": 1}'), (2, '{"facts_episode": 2}')]
    assert rows(r, "SELECT name, episode FROM facts WHERE episode IS NOT NULL OR name = 'infected(eve)' "
                   "ORDER BY fact") == [("infected(cid)", 1), ("contact(dan,eve)", 2), ("infected(eve)", None)]
    # each episode's own facts, none of the other's: episode 2 never saw infected(cid) set by a fact
    assert rows(r, "SELECT episode, rule FROM changes WHERE atom IN ('infected(cid)', 'contact(dan,eve)') "
                   "ORDER BY episode, seq") == [(1, "fact:infected(cid)"), (2, "fact:contact(dan,eve)"),
                                                (2, "spread")]
    code, out, _ = cli(capsys, "diff", r, "1", "2")
    assert code == 0 and "  fact only in 1: infected(cid):[1,1] @0" in out.splitlines()
    assert "  fact only in 2: contact(dan,eve):[1,1] @0" in out.splitlines()
    # without --run the same episodes are printed, each under its name
    code, out, _ = cli(capsys, "reason", *argv)
    assert code == 0 and [ln for ln in out.splitlines() if ln.startswith("episode")] == ["episode 1:", "episode 2:"]
    code, _, err = cli(capsys, "reason", *argv, "--repeat", "2")
    assert code == 1 and "--repeat gives them too" in err and err.count("\n") == 1


def test_a_negative_episode_in_a_fact_table_is_a_located_error(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "t.csv").write_text("atom,episode\np(a),0\np(b),-3\n")
    (tmp_path / "p.rules").write_text("q: q(X) <-0 p(X)\n")
    code, _, err = cli(capsys, "reason", tmp_path / "p.rules", "--facts-table", tmp_path / "t.csv", "--steps", "1")
    assert code == 1 and f"{tmp_path / 't.csv'}" in err and "row 2: episode -3 of p(b)" in err


def test_repeat_gives_identical_episodes(inputs: dict[str, Path], tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    record(capsys, tmp_path / "r", inputs["spread"], "--graph", inputs["contacts"], "--steps", "3", "--repeat", "3")
    assert rows(tmp_path / "r", "SELECT episode, count(*) FROM changes GROUP BY 1 ORDER BY 1") == [
        (0, 9), (1, 9), (2, 9)]
    code, out, _ = cli(capsys, "diff", tmp_path / "r", "0", "2")
    assert code == 0 and "no divergence: the same rules and facts" in out
    code, _, err = cli(capsys, "diff", tmp_path / "r", tmp_path / "r")  # which of its episodes?
    assert code == 1 and "has episodes 0, 1, 2: name one" in err


# ---- the reading commands ----------------------------------------------------------------------------

def test_trace(run: Path, capsys: pytest.CaptureFixture) -> None:
    # the graph's attributes are static facts: hidden by default, with a note, and shown by --static
    code, out, err = cli(capsys, "trace", run, "--episode", "0", "--label", "infected")
    assert code == 0 and "fact:infected(ann)" not in out and "1 row of static facts hidden" in err
    code, out, _ = cli(capsys, "trace", run, "--episode", "0", "--label", "infected", "--static")
    assert code == 0
    assert [ln.split() for ln in out.splitlines()[2:-1]] == [
        ["0", "ann", "infected", "[0,1]", "[1,1]", "fact:infected(ann)"],
        ["1", "bob", "infected", "[0,1]", "[1,1]", "spread"],
        ["2", "cid", "infected", "[0,1]", "[1,1]", "spread"],
        ["3", "eve", "infected", "[0,1]", "[1,1]", "spread"]]


def test_why_and_why_not(run: Path, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "why", run, "infected(eve)", "--episode", "0")
    lines = out.splitlines()
    assert code == 0 and lines[0].startswith("infected(eve) = [1,1] at the end of t=5: set at t=3 pass 0")
    assert "by spread (Δt=1; Y=eve, X=cid; body read at the end of t=2)" in lines[0]
    assert any("ok contact(cid,eve):[0.8,1] = [1,1]: set at t=0 pass 0 [0,1]->[1,1] by fact:contact(cid,eve)" in ln
               for ln in lines)
    assert any("ok masked(eve):[0,0] = [0,1]: never set (the default [0,1], read as [0,0]: %closed)" in ln
               for ln in lines)
    code, out, _ = cli(capsys, "why", run, "alarm(cid)", "-e", "0", "--json")
    assert code == 0 and json.loads(out)["tree"]["cause"]["name"] == "alarm"
    code, out, _ = cli(capsys, "why-not", run, "-e", "0", "--rule", "spread", "--grounding", "X=cid,Y=dan", "--at", "3")
    assert code == 0 and out.splitlines()[-1] == "first failed clause: #3 masked(dan):[0,0] (masked(dan) = [1,1])"


def test_sql_views_and_saved_queries(run: Path, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "sql", run, "SELECT source, target FROM edges WHERE source = 'cid' ORDER BY 2",
                       "--format", "csv")
    assert code == 0 and out.splitlines() == ["source,target", "cid,dan", "cid,eve"]
    for name in ("rule_coverage", "firings_per_episode", "episode_summary"):
        code, out, err = cli(capsys, "sql", run, "--query", name, "--format", "json")
        assert code == 0, err
    assert {r["rule"]: r["firings"] for r in json.loads(cli(capsys, "sql", run, "--query", "rule_coverage",
                                                            "--format", "json")[1])} == {"spread": 3, "alarm": 1}
    for name in ("actions_per_win", "steps_before_loss", "learner_events", "hid_behind_mountain"):
        code, out, err = cli(capsys, "sql", run, "--query", name)
        assert code == 1 and out == "" and err.count("\n") == 1
        assert f"saved query {name} reads games" in err
        assert ("is not a run of games" if name in ("actions_per_win", "steps_before_loss") else "has no board") in err
    code, out, _ = cli(capsys, "sql", SAMPLES / "base", "--query", "learner_events")  # a game run: as before
    assert code == 0 and "(3 rows)" in out
    code, out, _ = cli(capsys, "sql", "--list")
    assert "actions_per_win: " in out and "(game runs only)" in out


def test_diff_of_two_reasonings_says_what_one_changed_fact_changed(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The example of docs/store.md: the supply chain recorded, then again with one package patched."""
    argv = [EXAMPLES / "supply_chain.rules", "--graph", EXAMPLES / "supply_chain.graphml", "--steps", "8"]
    record(capsys, tmp_path / "before", *argv)
    record(capsys, tmp_path / "after", *argv, "--facts", EXAMPLES / "supply_chain_fix.rules")
    code, out, _ = cli(capsys, "diff", tmp_path / "before", tmp_path / "after")
    lines = out.splitlines()
    assert code == 0 and lines[1:3] == [
        "given:", f"  fact only in {tmp_path / 'after'}:0: patched(json-server-compat):[1,1] @0 static"]
    changed = int(lines[3].split()[3])
    assert lines[3] == f"at the end: {changed} atoms with another bound" and changed > 10
    assert lines[4].endswith(f"[1,1] in {tmp_path / 'before'}:0, [0,1] in {tmp_path / 'after'}:0")
    d = json.loads(cli(capsys, "diff", tmp_path / "before", tmp_path / "after", "--json")[1])
    assert d["end"]["count"] == changed == len(d["end"]["atoms"]) and not d["identical"]
    assert {"atom": "exposed(json-server-compat)", "lower_a": 1.0, "upper_a": 1.0, "lower_b": 0.0,
            "upper_b": 1.0} in d["end"]["atoms"]
    assert [f["literal"] for f in d["given"]["facts_only_in_b"]] == ["patched(json-server-compat):[1,1]"]
    # every atom the patch changed was exposed before and is not after
    assert {a["atom"].split("(")[0] for a in d["end"]["atoms"]} <= {"exposed", "alert", "patched"}
    code, out, _ = cli(capsys, "why", tmp_path / "before", "exposed(json-server-compat)", "--episode", "0")
    assert code == 0 and "by exposed (Δt=1; P=json-server-compat" in out.splitlines()[0]


def test_show_check_seal_and_runs(run: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    code, out, _ = cli(capsys, "show", run)
    lines = out.splitlines()
    assert code == 0 and "  board     none: a reasoning run (its episodes are reasonings, not games)" in lines
    assert "episodes  1 (1 converged)" in lines and "graph     5 nodes, 5 edges" in lines
    assert not any(ln.startswith("scenario") for ln in lines)
    graph_file = json.loads(rows(run, "SELECT config FROM run")[0][0])["sources"][1]["path"]
    assert f"  graph     {graph_file} ({Path(graph_file).stat().st_size:,} bytes)" in lines
    code, out, _ = cli(capsys, "check", run)
    assert code == 0 and out.splitlines()[-1] == "ok"
    sealed = tmp_path / "sealed"
    shutil.copytree(run, sealed)
    assert cli(capsys, "seal", sealed)[0] == 0 and (sealed / "run.duckdb").is_file()
    assert cli(capsys, "check", sealed)[1].splitlines()[-1] == "ok"
    assert rows(sealed, "SELECT count(*) FROM edges") == [(5,)] and rows(sealed, "SELECT board FROM run") == [(None,)]
    code, out, _ = cli(capsys, "why", sealed, "infected(eve)", "-e", "0")
    assert code == 0 and "by spread" in out.splitlines()[0]
    code, out, _ = cli(capsys, "runs", run.parent, sealed, "--format", "json")
    listed = {r["name"]: r for r in json.loads(out)}
    assert listed["contacts"]["status"] == listed["sealed"]["status"] == "finished"
    assert listed["contacts"]["rows"] == rows(run, "SELECT count(*) FROM changes")[0][0]


def test_a_pyreason_program_recorded_and_explained(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = record(capsys, tmp_path / "r", "--dialect", "pyreason", PYREASON / "hello_rules.txt", "--facts",
                 PYREASON / "hello_facts.csv", "--graph", PYREASON / "friends_graph.graphml", "--steps", "3",
                 "--pyreason-trace", tmp_path / "csv")
    assert "tracelab why" in out and list((tmp_path / "csv").glob("rule_trace_nodes_*.csv"))
    code, out, _ = cli(capsys, "why", tmp_path / "r", 'popular("Justin")', "--episode", "0", "--at", "2")
    lines = out.splitlines()
    assert code == 0 and "by rule_0 (Δt=1; X=Justin, Y=Mary, Z=Cat" in lines[0]
    assert "ok popular(Mary):[1,1] = [1,1]: set at t=1 pass 0 [0,1]->[1,1] by fact:popular_fact" in lines[1]
    config = json.loads(rows(tmp_path / "r", "SELECT config FROM run")[0][0])
    assert config["dialect"] == "pyreason" and "translation" not in config
    texts = dict(rows(tmp_path / "r", "SELECT role, text FROM raw.sources"))
    assert "rule_0: popular(X) <-1" in texts["translation"]
    assert texts["rules"] == (PYREASON / "hello_rules.txt").read_text()


# ---- the store without a game -----------------------------------------------------------------------

def test_a_run_declares_its_board_and_the_viewers_draw_only_those(run: Path) -> None:
    from tracelab.store import open_run
    from tracelab.store.kind import run_board
    from tracelab.viewers.board_state import board_of_run
    assert board_of_run(open_run(run)) is None
    # RuleSim's runs (tests/data/rulesim/base) are the grid game's; a spec world's run (the sample runs)
    # declares its spec's [board] in its config
    assert run_board(open_run(ROOT / "tests" / "data" / "rulesim" / "base")) == "gridworld"
    assert board_of_run(open_run(ROOT / "tests" / "data" / "rulesim" / "base")) is not None
    assert run_board(open_run(SAMPLES / "base")) is None and board_of_run(open_run(SAMPLES / "base")) is not None
    import importlib.util
    assert importlib.util.find_spec("tracelab.store.board") is None  # one board, in viewers/


def test_a_board_that_is_not_a_name_is_refused_in_one_line(run: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(run, bad)
    meta = json.loads((bad / "meta.json").read_text())
    (bad / "meta.json").write_text(json.dumps({**meta, "board": 5}))
    code, out, err = cli(capsys, "show", bad)
    assert code == 1 and out == "" and err.count("\n") == 1
    assert err.startswith(f"tracelab: error: {bad / 'meta.json'}: key 'board': expected a string") and "5" in err


def test_a_played_game_declares_its_board(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """GridWar through its spec: the run declares the spec's [board] (the default map's rows), which the
    TUI and the replay draw, not RuleSim's built-in `gridworld` board."""
    from tracelab.board import RUN_CONFIG_KEY
    code, _, err = cli(capsys, "play", "--scenario", "base", "--episodes", "1", "--run", tmp_path / "g")
    assert code == 0, err
    meta = json.loads((tmp_path / "g" / "meta.json").read_text())
    assert meta.get("board") is None and meta["config"][RUN_CONFIG_KEY]["rows"][2] == "....M..."
    # a saved query that needs a board reads it (it was refused: "has no board")
    from tracelab.store import open_run
    from tracelab.store.kind import can_read, has_board
    assert has_board(open_run(tmp_path / "g")) and can_read(open_run(tmp_path / "g"), "board")
    for name in ("learner_events", "hid_behind_mountain"):
        code, out, err = cli(capsys, "sql", tmp_path / "g", "--query", name)
        assert code == 0 and err == "" and "(1 row)" in out, (name, err)


def test_runs_written_before_the_edges_table_still_open_and_seal(run: Path, tmp_path: Path) -> None:
    """A live run whose manifest has no `edges` (and whose facts have no `episode`): as every run written
    before them; it opens with an empty edges table, checks, seals."""
    import pyarrow.parquet as pq

    from tracelab.store import open_run, seal_run
    from tracelab.store.check import check_run
    old = tmp_path / "old"
    shutil.copytree(run, old)
    manifest = json.loads((old / "parts" / "manifest.json").read_text())
    del manifest["tables"]["edges"]
    (old / "parts" / "manifest.json").write_text(json.dumps(manifest))
    shutil.rmtree(old / "parts" / "edges")
    for f in manifest["tables"]["facts"]:
        pq.write_table(pq.read_table(old / "parts" / f).drop_columns(["episode"]), old / "parts" / f)
    con = open_run(old)
    assert con.execute("SELECT count(*) FROM edges").fetchall() == [(0,)]
    assert con.execute("SELECT count(*), count(episode) FROM facts").fetchall() == [(6, 0)]
    con.close()
    assert check_run(old).ok
    seal_run(old)
    assert rows(old, "SELECT count(*) FROM edges") == [(0,)]
    assert rows(old, "SELECT count(*) FROM changes") == rows(run, "SELECT count(*) FROM changes")


def test_graph_facts_as_columns_are_the_graphs_fact_objects(inputs: dict[str, Path], tmp_path: Path) -> None:
    """graph_fact_table (a million facts without a Python object each) against Graph.fact(i), on quoted
    node names, an undirected edge, bounds that are not [1,1] and a fact table's windows."""
    from tracelab.engine import load_fact_table, load_graphml
    from tracelab.engine.program import Program
    from tracelab.store.convert import program_tables
    from tracelab.store.graph_tables import graph_fact_table
    (tmp_path / "g.graphml").write_text(GRAPH.replace('edgedefault="directed"', 'edgedefault="undirected"')
                                        .replace('"bob"', '"Big Bob"'))
    (tmp_path / "t.csv").write_text('atom,lower,start,end\n"contact(\'x y\',ann)",0.25,1,3\n')
    graph = load_graphml(tmp_path / "g.graphml").concat(load_fact_table(tmp_path / "t.csv"))
    columns = graph_fact_table(graph, first_id=4).to_pylist()
    objects = program_tables(Program(), graph.facts)["facts"].to_pylist()
    assert len(columns) == len(objects) == graph.n_facts == 11  # the undirected edges' facts both ways
    assert [{**c, "fact": c["fact"] - 4} for c in columns] == objects
    assert {c["name"] for c in columns} >= {'contact(ann,"Big Bob")', 'contact("Big Bob",ann)',
                                             'contact("x y",ann)'}
    assert np.array_equal(graph.episodes, np.full(11, -1))


def test_bench_reason_store_quick(capsys: pytest.CaptureFixture) -> None:
    from tracelab.bench import reason_store
    r = reason_store.run(quick=True, repeats=1, nodes=2_000)
    assert r["edges"] == 10_000 and r["change_rows"] > 10_000 and r["ratio"] > 0
    assert r["changes_rows_per_s"]["median"] > 0 and r["run_fresh_peak_rss_bytes"] > 0
    assert "reason --run vs --no-trace" in reason_store.report(r)


def test_the_sample_reasoning_run_opens_from_a_fresh_clone(capsys: pytest.CaptureFixture) -> None:
    """sample_runs/supply-chain: the supply-chain example recorded and sealed (sample_runs/regenerate.sh)."""
    run = SAMPLES / "supply-chain"
    assert (run / "run.duckdb").is_file()
    assert rows(run, "SELECT board, status FROM run") == [(None, "finished")]
    assert rows(run, "SELECT count(*) FROM edges") == [(6667,)]
    assert rows(run, "SELECT count(*) FROM raw.nodes") == [(2430,)]
    assert rows(run, "SELECT episode, outcome FROM episodes") == [(0, "converged")]
    code, out, _ = cli(capsys, "why", run, "alert(sam-gray)", "--episode", "0", "--depth", "2")
    assert code == 0 and out.startswith("alert(sam-gray) = [1,1] at the end of t=7: set at t=5")
