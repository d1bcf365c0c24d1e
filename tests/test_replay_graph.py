"""`tracelab replay` of a run without a board (a reasoning run, `tracelab reason --run`), headless: recordings
saved with --save and read back through rerun's chunk reader: the graph's nodes at the GraphML's x/y (or a
layout, the same every time), the edges as they appear, each node's colour step by step, the rule log, the
why documents, the user's errors in one line, and the supply-chain sample's thousands of nodes."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_replay import latest_at, read_rrd
from test_replay_pictures import blueprint_views

from tracelab.cli import main
from tracelab.store.reader import open_run
from tracelab.store.why import explain, render_why
from tracelab.viewers.replay import style
from tracelab.viewers.replay.graph_layout import MAX_FORCE_NODES, fit_given, layout

SAMPLES = Path(__file__).resolve().parent.parent / "sample_runs"

NODES = {"a": (0.1, 0.9), "b": (0.4, 0.7), "c": (0.7, 0.5), "d": (0.9, 0.2), "e": (0.3, 0.1)}
KEYS = """<key id="x" for="node" attr.name="x" attr.type="double"/>
<key id="y" for="node" attr.name="y" attr.type="double"/>
"""


def graphml(positions: bool) -> str:
    """a -> b -> c -> d linked (an edge attribute), d -> e a bare edge; `size` on a alone."""
    nodes = "".join(f'<node id="{n}">' + (f'<data key="x">{x}</data><data key="y">{y}</data>' if positions else "")
                    + ('<data key="size">0.5</data>' if n == "a" else "") + "</node>\n"
                    for n, (x, y) in NODES.items())
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
{KEYS if positions else ""}<key id="size" for="node" attr.name="size" attr.type="double"/>
<key id="link" for="edge" attr.name="link" attr.type="boolean"/>
<graph edgedefault="directed">
{nodes}<edge source="a" target="b"><data key="link">true</data></edge>
<edge source="b" target="c"><data key="link">true</data></edge>
<edge source="c" target="d"><data key="link">true</data></edge>
<edge source="d" target="e"/>
</graph></graphml>
"""


# infected spreads one link a step from a (b at t=1, c at 2, d at 3; e never: its edge has no link), and
# each step draws a new edge near(X,Y) behind it
RULES = """infected(a)
spread: infected(Y) <-1 infected(X), link(X,Y)
near:   near(X,Y) <-1 infected(X), link(X,Y)
"""


def record(tmp: Path, positions: bool) -> Path:
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / "g.graphml").write_text(graphml(positions))
    (tmp / "p.rules").write_text(RULES)
    assert main(["reason", str(tmp / "p.rules"), "--graph", str(tmp / "g.graphml"), "--steps", "5",
                 "--run", str(tmp / "run")]) == 0
    return tmp / "run"


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record(tmp_path_factory.mktemp("graph"), positions=True)


def replayed(run: Path, out: Path, *args: str) -> dict[str, list[dict]]:
    assert main(["replay", str(run), "--save", str(out), *args]) == 0
    (recording,) = read_rrd(out).values()
    return recording


@pytest.fixture(scope="module")
def graph(run: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[dict]]:
    return replayed(run, tmp_path_factory.mktemp("rrd") / "g.rrd", "--why", "infected(d)")


def rgb(packed: int) -> tuple[int, int, int]:
    return (packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255


def at(rows: list[dict], step: int, column: str) -> object:
    """`column` in force at `step`: its last row at or before it, else its static row."""
    found = latest_at(rows, step, column)
    return found if found is not None else next((r[column] for r in rows if "step" not in r and r.get(column)), None)


def colours_at(rows: list[dict], step: int) -> dict[str, tuple[int, int, int]]:
    """node -> its colour in force at `step`."""
    ids = at(rows, step, "GraphNodes:node_ids")
    return dict(zip(ids, map(rgb, latest_at(rows, step, "GraphNodes:colors"))))


def edges_at(rows: list[dict], step: int) -> set[tuple[str, str]]:
    return {(e["first"], e["second"]) for e in latest_at(rows, step, "GraphEdges:edges")}


def colour(lower: float, upper: float) -> tuple[int, int, int]:
    return tuple(int(v) for v in style.bound_colors(np.array([lower]), np.array([upper]))[0])


RED, GREY = colour(1, 1), colour(0, 1)


def test_the_nodes_stand_where_the_graphml_puts_them(graph: dict[str, list[dict]]) -> None:
    rows = graph["/graph"]
    ids = latest_at(rows, 0, "GraphNodes:node_ids")
    assert ids[:5] == list(NODES)
    given = np.array([(x, -y) for x, y in NODES.values()])          # y up in the file, down in the viewer
    drawn = np.array(latest_at(rows, 0, "GraphNodes:positions"))[:5]
    assert np.allclose(drawn, fit_given(given), atol=1e-3)


def test_the_edges_appear_at_the_steps_their_atoms_do(graph: dict[str, list[dict]]) -> None:
    rows = graph["/graph"]
    graph_edges = {("a", "b"), ("b", "c"), ("c", "d"), ("d", "e")}
    assert edges_at(rows, 0) == graph_edges
    assert edges_at(rows, 1) == graph_edges | {("a", "b")}                  # near(a,b): a pair twice
    near = [e for r in rows if r.get("GraphEdges:edges") for e in [r["step"]]]
    assert near == [0, 1, 2, 3]                       # a row only where the edges changed (none at t=4)
    counts = [len(latest_at(rows, s, "GraphEdges:edges")) for s in range(5)]
    assert counts == [4, 5, 6, 7, 7]
    # a small graph labels its edges: a label node per pair, naming the predicates of its edges then
    for step, want in ((0, {"a->b": "link", "b->c": "link", "c->d": "link", "d->e": "edge"}),
                       (2, {"a->b": "link, near", "b->c": "link, near", "c->d": "link", "d->e": "edge"})):
        labels = dict(zip(latest_at(rows, step, "GraphNodes:node_ids"), latest_at(rows, step, "GraphNodes:labels")))
        assert {k: v for k, v in labels.items() if "->" in k} == want


def test_each_nodes_colour_is_its_bound_of_the_colour_predicate_step_by_step(
        run: Path, graph: dict[str, list[dict]], tmp_path: Path) -> None:
    rows = graph["/graph"]
    infected_at = {"a": 0, "b": 1, "c": 2, "d": 3}
    for step in range(5):
        colours = colours_at(rows, step)
        for node in NODES:
            want = RED if node in infected_at and infected_at[node] <= step else GREY
            assert colours[node] == want, (step, node)
    assert [r["step"] for r in rows if r.get("GraphNodes:colors")] == [0, 1, 2, 3]    # only what changed
    # another predicate: size is [0.5,0.5] on a, never set elsewhere, and never changes (this small graph's
    # node rows still follow its edges' labels: the supply-chain test checks rows only where colours change)
    sized = replayed(run, tmp_path / "size.rrd", "--color-by", "size")["/graph"]
    assert {k: v for k, v in colours_at(sized, 4).items() if k in NODES} == {
        "a": colour(0.5, 0.5), "b": GREY, "c": GREY, "d": GREY, "e": GREY}
    assert all(colours_at(sized, s)["a"] == colour(0.5, 0.5) for s in range(5))
    views = blueprint_views(tmp_path / "size.rrd")
    assert any(name.startswith("Graph: size") for name in views), list(views)


def test_the_default_colour_is_the_predicate_that_changed_most_over_nodes(run: Path, tmp_path: Path) -> None:
    replayed(run, tmp_path / "d.rrd")
    assert any(name.startswith("Graph: infected") for name in blueprint_views(tmp_path / "d.rrd"))


def test_the_rule_log_holds_each_steps_firings(run: Path, graph: dict[str, list[dict]]) -> None:
    log = graph["/rules/log"]
    at2 = {(r["TextLog:level"][0], r["TextLog:text"][0]) for r in log if r["step"] == 2}
    assert at2 == {("spread", "spread(Y=c, X=b): infected(c) [0,1] -> [1,1]"),
                   ("near", "near(X=b, Y=c): near(b,c) [0,1] -> [1,1]")}
    con = open_run(run)
    assert len(log) == con.execute("SELECT count(*) FROM firings").fetchall()[0][0] == 6


def test_the_why_documents_show_the_named_atom_as_tracelab_why_does(run: Path, graph: dict[str, list[dict]]) -> None:
    docs = {r["step"]: r["TextDocument:text"][0] for r in graph["/why"]}
    assert sorted(docs) == [0, 1, 2, 3, 4]
    con = open_run(run)
    for step in (3, 4):
        assert render_why(explain(con, 0, "infected(d)", step), step) in docs[step]
    assert "### Why infected(d)" in docs[2] and "never set" in docs[2]
    assert "- changed: infected 1, near 1" in docs[3]
    assert "- edges: link 3, near 3, edge 1" in docs[3]
    assert "- fired: 2 (spread 1, near 1)" in docs[3]


@pytest.mark.parametrize("args, message", [
    (["--color-by", "nope"], "no predicate 'nope' over nodes in this run (--color-by); its predicates: "
                             "infected, size, x, y"),
    (["--why", "infected(zz)"], "--why infected(zz): no node 'zz' in this run; its nodes: a, b, c, d, e"),
    (["--why", "near(d,e)"], "--why near(d,e): atom 'near(d,e)' never occurs in this run"),
    (["--outcome", "win"], "no episode of this run matches"),
])
def test_user_errors_are_one_line(run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  args: list[str], message: str) -> None:
    assert main(["replay", str(run), *args, "--save", str(tmp_path / "x.rrd")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tracelab: error: ") and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "x.rrd").exists()


def test_color_by_on_a_run_drawn_on_its_board_is_a_one_line_error(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(SAMPLES / "base"), "--color-by", "alive", "--save", str(tmp_path / "x.rrd")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--color-by colours a graph's nodes" in err, err


def test_a_graph_without_positions_gets_one_layout_the_same_every_time(tmp_path: Path) -> None:
    run = record(tmp_path / "plain", positions=False)
    first = np.array(latest_at(replayed(run, tmp_path / "1.rrd")["/graph"], 0, "GraphNodes:positions"))[:5]
    second = np.array(latest_at(replayed(run, tmp_path / "2.rrd")["/graph"], 0, "GraphNodes:positions"))[:5]
    assert np.array_equal(first, second)
    apart = np.sqrt(((first[:, None] - first[None]) ** 2).sum(-1)) + np.eye(5) * 1e9
    assert apart.min() > style.NODE_RADIUS                               # no two nodes on each other


def test_past_the_force_layouts_limit_nodes_go_on_a_spiral_without_overlapping() -> None:
    n = MAX_FORCE_NODES + 1
    pos = layout(n, np.zeros((0, 2), np.int64))
    assert pos.shape == (n, 2) and np.isfinite(pos).all()
    sample = pos[::97]
    apart = np.sqrt(((sample[:, None] - sample[None]) ** 2).sum(-1)) + np.eye(len(sample)) * 1e9
    assert apart.min() > style.NODE_RADIUS


def test_the_supply_chain_sample_replays_its_thousands_of_nodes(tmp_path: Path) -> None:
    """2,430 nodes and 6,667 edges: drawn once, a colour row only at the steps where `exposed` (the
    default: the predicate with the most changes) changed, red at the end where exposed is [1,1]."""
    out = tmp_path / "sc.rrd"
    done = subprocess.run([sys.executable, "-m", "tracelab.cli", "replay", str(SAMPLES / "supply-chain"),
                           "--why", "alert(sam-gray)", "--save", str(out)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    rows = read_rrd(out)["supply-chain/episode-0"]["/graph"]
    con = open_run(SAMPLES / "supply-chain")
    n_nodes, n_edges = (con.execute(f"SELECT count(*) FROM raw.{t}").fetchall()[0][0] for t in ("nodes", "edges"))
    assert len(at(rows, 0, "GraphNodes:node_ids")) == n_nodes == 2430
    assert len(latest_at(rows, 0, "GraphEdges:edges")) == n_edges == 6667
    changed = [t for (t,) in con.execute("SELECT DISTINCT t FROM changes WHERE label = 'exposed' ORDER BY t")
               .fetchall()]
    assert [r["step"] for r in rows if r.get("GraphNodes:colors")] == sorted({0, *changed})
    exposed = {n for (n,) in con.execute("SELECT node FROM changes WHERE label = 'exposed' AND new_lower = 1")
               .fetchall()}
    last = colours_at(rows, 7)
    assert {n for n, c in last.items() if c == RED} == exposed and len(exposed) > 1000
    assert sum(r["step"] == 5 for r in read_rrd(out)["supply-chain/episode-0"]["/rules/log"]) == \
        con.execute("SELECT count(*) FROM firings WHERE t = 5").fetchall()[0][0]
    assert out.stat().st_size < 4 << 20                # the graph once, the colours 6 times: not per node


def test_live_follows_a_reasoning_run_being_written(tmp_path: Path) -> None:
    """Three reasonings (--repeat 3) recorded by another process; --live sends each as it ends, until the
    run stops (if the run ends first, it sends the three at once)."""
    run_dir, out = tmp_path / "live", tmp_path / "live.rrd"
    examples = Path(__file__).resolve().parent.parent / "rules" / "examples"
    reason = subprocess.Popen([sys.executable, "-m", "tracelab.cli", "reason", str(examples / "supply_chain.rules"),
                               "--graph", str(examples / "supply_chain.graphml"), "--steps", "8", "--repeat", "3",
                               "--run", str(run_dir)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not (run_dir / "parts" / "manifest.json").exists():
            assert reason.poll() is None or (run_dir / "parts" / "manifest.json").exists(), reason.stderr.read()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        done = subprocess.run([sys.executable, "-m", "tracelab.cli", "replay", str(run_dir), "--live", "--save",
                               str(out)], capture_output=True, text=True, timeout=300, check=False)
        assert done.returncode == 0, done.stderr
        assert "each episode is sent as it ends" in done.stderr
    finally:
        reason.wait(timeout=120)
    assert reason.returncode == 0
    recordings = read_rrd(out)
    assert sorted(recordings) == [f"live/episode-{e}" for e in range(3)]
    assert all(len(at(r["/graph"], 0, "GraphNodes:node_ids")) == 2430 for r in recordings.values())


def test_the_rule_log_keeps_at_most_its_limit_of_firings_a_step_and_counts_the_rest(tmp_path: Path) -> None:
    """2,100 nodes fire one rule each at t=1: the log keeps the first MAX_LOGGED_FIRINGS (in the engine's
    order) and one line saying how many more and how to list them."""
    from tracelab.viewers.replay.graph_run import MAX_LOGGED_FIRINGS
    n = MAX_LOGGED_FIRINGS + 100
    nodes = "".join(f'<node id="n{i}"><data key="p">true</data></node>\n' for i in range(n))
    (tmp_path / "g.graphml").write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
<key id="p" for="node" attr.name="p" attr.type="boolean"/>
<graph edgedefault="directed">
{nodes}</graph></graphml>
""")
    (tmp_path / "p.rules").write_text("q: q(X) <-1 p(X)\n")
    assert main(["reason", str(tmp_path / "p.rules"), "--graph", str(tmp_path / "g.graphml"), "--steps", "3",
                 "--run", str(tmp_path / "run")]) == 0
    log = replayed(tmp_path / "run", tmp_path / "r.rrd")["/rules/log"]
    at1 = [(r["TextLog:level"][0], r["TextLog:text"][0]) for r in log if r["step"] == 1]
    assert len(at1) == MAX_LOGGED_FIRINGS + 1
    assert at1[0] == ("q", "q(X=n0): q(n0) [0,1] -> [1,1]")
    assert at1[-1] == ("more", "... and 100 more firings at t=1 (tracelab trace RUN --episode 0 --from 1 --to 1)")


def test_a_graph_too_big_to_draw_is_refused_in_one_line_before_it_is_read(
        run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The limits are counted in SQL first (a stranger's run of ten million nodes is not read to find out);
    here lowered to this 5-node graph's size, as a graph past 100,000 nodes takes minutes to record."""
    from tracelab.viewers.replay import graph_run
    monkeypatch.setattr(graph_run, "MAX_NODES", 4)
    assert main(["replay", str(run), "--save", str(tmp_path / "x.rrd")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "this run's graph has 5 nodes and up to 10 edges; the replay draws at most 4 " \
                                   "nodes" in err, err
