"""GraphML input: attributes written by networkx come back as static facts with the right bounds."""
from __future__ import annotations

import json
import re
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from tracelab.cli import main as cli_main
from tracelab.engine import (
    Engine,
    Graph,
    ProgramCheckError,
    check_program,
    load_fact_table,
    load_graphml,
    load_program,
    parse_program,
)
from tracelab.engine.program import Literal, Term, constant_text


def facts_of(g: Graph) -> set[tuple[str, tuple[str, ...], float, float]]:
    out = set()
    for f in g.facts:
        assert f.static and f.start == f.end == 0 and not f.literal.negated
        out.add((f.literal.pred, tuple(t.name for t in f.literal.args), f.literal.lower, f.literal.upper))
    return out


def write(tmp_path: Path, g: nx.Graph, name: str = "g.graphml") -> Path:
    path = tmp_path / name
    nx.write_graphml(g, path)
    return path


def test_node_and_directed_edge_attributes_round_trip(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_node("red-agent-1", agent=True, health=0.75, team_red=1, dead=False)
    g.add_node("16", cell=True, alarm="0.2,0.9", danger="[0, .5]")
    g.add_node("24")  # no attributes: a node without facts
    g.add_edge("red-agent-1", "16", atLoc=1.0, seen="[0.5,1]")
    g.add_edge("24", "16", downLoc=True)
    graph = load_graphml(write(tmp_path, g))
    assert graph.nodes == ["red-agent-1", "16", "24"]
    assert facts_of(graph) == {
        ("agent", ("red-agent-1",), 1.0, 1.0),
        ("health", ("red-agent-1",), 0.75, 0.75),
        ("team_red", ("red-agent-1",), 1.0, 1.0),
        ("dead", ("red-agent-1",), 0.0, 0.0),
        ("cell", ("16",), 1.0, 1.0),
        ("alarm", ("16",), 0.2, 0.9),
        ("danger", ("16",), 0.0, 0.5),
        ("atLoc", ("red-agent-1", "16"), 1.0, 1.0),
        ("seen", ("red-agent-1", "16"), 0.5, 1.0),
        ("downLoc", ("24", "16"), 1.0, 1.0),  # directed: one direction only
    }
    assert len(graph.facts) == 10
    assert graph.predicates() == {"agent": 1, "health": 1, "team_red": 1, "dead": 1, "cell": 1, "alarm": 1,
                                  "danger": 1, "atLoc": 2, "seen": 2, "downLoc": 2}


def test_undirected_edges_give_both_directions(tmp_path: Path) -> None:
    g = nx.Graph()
    g.add_edge("a", "b", adj=True)
    g.add_edge("c", "c", adj=0.5)  # a self-loop once
    graph = load_graphml(write(tmp_path, g))
    assert sorted(f.text for f in graph.facts) == ["adj(a,b)", "adj(b,a)", "adj(c,c)"]
    assert facts_of(graph) == {("adj", ("a", "b"), 1.0, 1.0), ("adj", ("b", "a"), 1.0, 1.0),
                               ("adj", ("c", "c"), 0.5, 0.5)}


def test_graph_predicates_feed_check_program(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_node("n1", agent=True)
    g.add_edge("n1", "n2", atLoc=True)
    graph = load_graphml(write(tmp_path, g))
    p = parse_program("h(A) <-0 agent(A), atLoc(A,X)\n")
    assert len(p.warnings) == 2
    check_program(p, graph.predicates())
    assert p.warnings == []
    clash = parse_program("h(A) <-0 atLoc(A)\n", "c.rules")
    with pytest.raises(ProgramCheckError, match="with 1 argument here but with 2 arguments in the graph"):
        check_program(clash, graph.predicates())


def test_fact_literals_are_ground_constants(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_node("Cell 3", agent=True)  # any node id is a constant (quoted in rules)
    graph = load_graphml(write(tmp_path, g))
    assert graph.facts[0].literal == Literal("agent", (Term("Cell 3", False),))


@pytest.mark.parametrize("node_attrs,fragment", [
    ({"health": 3.5}, "node 'n1', attribute 'health': value 3.5 is not a bound"),
    ({"health": -1}, "node 'n1', attribute 'health': value -1 is not a bound"),
    ({"color": "red"}, "node 'n1', attribute 'color': value 'red' is not a bound"),
    ({"alarm": "0.9,0.2"}, "node 'n1', attribute 'alarm': value '0.9,0.2' is not a bound"),
    ({"alarm": "[0.2,0.9"}, "value '[0.2,0.9' is not a bound"),
    ({"Color": True}, "node 'n1', attribute 'Color': not a predicate name"),
    ({"x-y": True}, "attribute 'x-y': not a predicate name"),
])
def test_bad_node_attributes(tmp_path: Path, node_attrs: dict, fragment: str) -> None:
    g = nx.DiGraph()
    g.add_node("n1", **node_attrs)
    path = write(tmp_path, g)
    with pytest.raises(ProgramCheckError) as e:
        load_graphml(path)
    assert e.value.file == str(path)
    assert fragment in e.value.message
    assert e.value.line > 0 and str(e.value).startswith(f"{path}:{e.value.line}:{e.value.column}: error: ")


def test_bad_edge_attribute_names_the_edge(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_edge("a", "b", weight=7)
    with pytest.raises(ProgramCheckError, match=r"edge \('a', 'b'\), attribute 'weight': value 7 is not a bound"):
        load_graphml(write(tmp_path, g))


def test_attribute_on_nodes_and_edges_is_an_arity_clash(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_node("a", near=True)
    g.add_edge("a", "b", near=True)
    with pytest.raises(ProgramCheckError, match="attribute 'near': set on nodes and on edges"):
        load_graphml(write(tmp_path, g))


GRAPHML_WITH_DEFAULTS_AND_IDS = """<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
  <key id="d0" for="node" attr.name="cell" attr.type="boolean"><default>true</default></key>
  <key id="d1" for="edge" attr.name="road" attr.type="double"/>
  <graph id="G" edgedefault="directed">
    <node id="n0"/>
    <node id="n1"><data key="d0">false</data></node>
    <edge id="e0" source="n0" target="n1"><data key="d1">0.25</data></edge>
  </graph>
</graphml>
"""


def test_key_defaults_apply_and_edge_ids_are_not_labels(tmp_path: Path) -> None:
    path = tmp_path / "h.graphml"
    path.write_text(GRAPHML_WITH_DEFAULTS_AND_IDS)
    graph = load_graphml(path)
    assert facts_of(graph) == {("cell", ("n0",), 1.0, 1.0), ("cell", ("n1",), 0.0, 0.0),
                               ("road", ("n0", "n1"), 0.25, 0.25)}


def test_unreadable_file_is_a_located_error(tmp_path: Path) -> None:
    path = tmp_path / "broken.graphml"
    path.write_text("<graphml><graph>")
    with pytest.raises(ProgramCheckError) as e:
        load_graphml(path)
    assert e.value.file == str(path) and "not a readable GraphML file" in e.value.message


NODE_WITHOUT_ID = """<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
  <graph id="G" edgedefault="directed"><node id="a"/><node/></graph>
</graphml>
"""


def test_node_without_id_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "noid.graphml"
    path.write_text(NODE_WITHOUT_ID)
    with pytest.raises(ProgramCheckError, match="<node> has no id"):
        load_graphml(path)


@pytest.mark.parametrize("node", ["X", "a b(c)", "Cell 3", 'say "hi"', "#1", "_x"])
def test_node_ids_that_are_not_plain_constants_print_quoted_and_parse_back(tmp_path: Path, node: str) -> None:
    g = nx.DiGraph()
    g.add_node(node, agent=True)
    g.add_edge(node, "b", link=True)
    graph = load_graphml(write(tmp_path, g))
    eng = Engine(parse_program("seen(Y) <-0 agent(X), link(X,Y)\n"), graph)
    eng.run(1)
    final = eng.interpretation()
    assert set(final) == {f"agent({constant_text(node)})", f"link({constant_text(node)},b)", "seen(b)"}
    for text, bound in final.items():  # every printed atom parses back to the same atom
        assert eng.query(text) == bound
    assert eng.grounding_text(0) == f"Y=b, X={constant_text(node)}"  # head variables first
    assert constant_text(node) != node


def test_node_ids_the_language_cannot_write_are_errors(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_node("""both"'quotes""", agent=True)
    with pytest.raises(ProgramCheckError, match="cannot be a constant of the rule language: it holds both"):
        load_graphml(write(tmp_path, g))


def test_engine_refuses_an_arity_clash_with_the_graph(tmp_path: Path) -> None:
    g = nx.DiGraph()
    g.add_edge("a", "b", link=True)
    graph = load_graphml(write(tmp_path, g))
    with pytest.raises(ProgramCheckError, match="predicate 'link' is used with 1 argument here but with 2 "
                                                "arguments in the graph") as e:
        Engine(parse_program("h(A) <-0 link(A)\n", "c.rules"), graph)
    assert (e.value.file, e.value.line) == ("c.rules", 1)


def test_reason_with_a_graph(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    g = nx.DiGraph()
    g.add_node("a", infected=True)
    g.add_edge("a", "b", link=True)
    graph_file = write(tmp_path, g)
    rules = tmp_path / "spread.rules"
    rules.write_text("infected(X) <-1 infected(Y), link(Y,X)\n")
    assert cli_main(["reason", str(rules), "--graph", str(graph_file), "--steps", "2", "--no-trace"]) == 0
    out, err = capsys.readouterr()
    assert "never set" not in err  # the graph sets infected and link
    assert "infected(b): [1,1]" in out
    clash = tmp_path / "clash.rules"
    clash.write_text("h(X) <-0 infected(X)\nh(X) <-0 link(X)\n")
    assert cli_main(["reason", str(clash), "--graph", str(graph_file), "--steps", "1"]) == 1
    err = capsys.readouterr().err
    assert err == (f"tracelab: error: {clash}:2:10: predicate 'link' is used with 1 argument here but with 2 "
                   "arguments in the graph\n")


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE graphml [
  <!ENTITY lol "lol">
  <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
  <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
]>
<graphml><graph><node id="&lol3;"/></graph></graphml>
"""

EXTERNAL_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE graphml [<!ENTITY secret SYSTEM "file://{secret}">]>
<graphml><graph><node id="a"><data key="d0">&secret;</data></node></graph></graphml>
"""


def test_entity_declarations_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "laughs.graphml"
    path.write_text(BILLION_LAUGHS)
    with pytest.raises(ProgramCheckError, match="declares the entity 'lol': entity declarations are refused") as e:
        load_graphml(path)
    assert e.value.line == 3


def test_external_entities_are_never_read(tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("0.5,0.5")
    path = tmp_path / "xxe.graphml"
    path.write_text(EXTERNAL_ENTITY.format(secret=secret))
    with pytest.raises(ProgramCheckError, match="entity declarations are refused") as e:
        load_graphml(path)
    assert "0.5" not in str(e.value)


def test_an_undeclared_entity_is_a_located_error(tmp_path: Path) -> None:
    path = tmp_path / "undeclared.graphml"
    path.write_text('<graphml><graph><node id="&x;"/></graph></graphml>')
    with pytest.raises(ProgramCheckError, match="not a readable GraphML file: undefined entity") as e:
        load_graphml(path)
    assert (e.value.line, e.value.column) == (1, 17)  # the element that holds it


def test_a_value_that_is_not_its_declared_type(tmp_path: Path) -> None:
    path = tmp_path / "int.graphml"
    path.write_text('<graphml><key id="d0" for="node" attr.name="hp" attr.type="int"/>\n<graph>'
                    '<node id="a"><data key="d0">abc</data></node></graph></graphml>')
    with pytest.raises(ProgramCheckError, match="node 'a', attribute 'hp': value 'abc' is not of type int") as e:
        load_graphml(path)
    assert e.value.line == 2


def _both_readers(path: Path) -> tuple[Graph, Graph]:
    from tracelab.engine.graph import _scan, _to_graph
    from tracelab.engine.graphml_expat import read_graphml_expat
    raw = _scan(str(path), path.read_bytes())
    assert raw is not None, "the compiled scanner should take this file"
    return _to_graph(raw), _to_graph(read_graphml_expat(str(path)))


def _same_graph(a: Graph, b: Graph) -> None:
    assert a.nodes == b.nodes and a.labels == b.labels and a.label_arity == b.label_arity
    assert np.array_equal(a.fact_label, b.fact_label) and np.array_equal(a.fact_args, b.fact_args)
    assert np.array_equal(a.fact_bounds, b.fact_bounds)


@pytest.mark.parametrize("directed", [True, False])
def test_the_scanner_and_the_expat_reader_agree(tmp_path: Path, directed: bool) -> None:
    rng = np.random.default_rng(3)
    g = nx.DiGraph() if directed else nx.Graph()
    for i in range(60):
        g.add_node(f"n{i}" if i % 7 else f"N {i}", **({"hp": float(rng.random())} if i % 3 else {"cell": bool(i % 2)}))
    for _ in range(200):
        u, v = (int(x) for x in rng.integers(0, 70, 2))  # some ends are not declared nodes
        g.add_edge(f"n{u}", f"n{v}", link=True, w=f"[{rng.random() / 2:.3f},{0.5 + rng.random() / 2:.3f}]")
    path = write(tmp_path, g)
    fast, full = _both_readers(path)
    _same_graph(fast, full)
    assert fast.n_facts > 400


SCANNER_CORNERS = """<?xml version="1.0" encoding="UTF-8"?>
<!-- a comment with <node id="fake"/> in it -->
<g:graphml xmlns:g="http://graphml.graphdrawing.org/xmlns">
  <g:key id="k" for="node" attr.name="hp" attr.type="double"><g:default>0.5</g:default></g:key>
  <g:key id="e" for="edge" attr.name="near" attr.type="boolean"/>
  <g:graph edgedefault="undirected">
    <g:node id='a'><g:data key="k"> 1e-1 </g:data></g:node>
    <g:node id="b"/>
    <g:edge source="a" target="b" directed="true"><g:data key="e">TRUE</g:data></g:edge>
    <g:edge target="a" source="b"><g:data key="e">0</g:data></g:edge>
  </g:graph>
</g:graphml>
"""


def test_scanner_corners_prefixes_comments_defaults_directions(tmp_path: Path) -> None:
    path = tmp_path / "corners.graphml"
    path.write_text(SCANNER_CORNERS)
    fast, full = _both_readers(path)
    _same_graph(fast, full)
    assert fast.nodes == ["a", "b"]
    assert facts_of(fast) == {("hp", ("a",), 0.1, 0.1), ("hp", ("b",), 0.5, 0.5), ("near", ("a", "b"), 1.0, 1.0),
                              ("near", ("b", "a"), 0.0, 0.0), ("near", ("a", "b"), 0.0, 0.0)}


@pytest.mark.parametrize("text", [
    '<graphml><graph><node id="a"><data key="k">&lt;</data></node></graph></graphml>',  # a reference
    '<graphml><graph><node id="a"/></graph></graphml><graphml/>',  # two roots
    '<graphml><graph><node id="a"></graph></graphml>',  # mismatched end tag
    '<graphml><graph><node id="a"><data key="k"><b/></data></node></graph></graphml>',  # element in data
])
def test_files_outside_the_scanner_subset_go_to_the_expat_reader(tmp_path: Path, text: str) -> None:
    from tracelab.engine.graph import _scan
    assert _scan("x", text.encode()) is None


def test_fact_tables_csv_and_parquet(tmp_path: Path) -> None:
    import duckdb
    csv = tmp_path / "facts.csv"
    csv.write_text('atom,lower,upper,start,end\n"link(a,b)",1,1,0,0\n"infected(""Cell 3"")",0.5,1,0,0\n'
                   "~alarm(b),0.2,0.4,1,3\n")
    g = load_fact_table(csv)
    assert g.nodes == ["a", "b", "Cell 3"]
    assert facts_of_with_windows(g) == [("link", ("a", "b"), 1.0, 1.0, 0, 0, False),
                                        ("infected", ("Cell 3",), 0.5, 1.0, 0, 0, False),
                                        ("alarm", ("b",), 0.6, 0.8, 1, 3, False)]
    parquet = tmp_path / "facts.parquet"
    con = duckdb.connect()
    con.execute(f"COPY (SELECT 'link(b,c)' AS atom, true AS static) TO '{parquet}' (FORMAT parquet)")
    con.close()
    both = g.concat(load_fact_table(parquet))
    assert both.nodes == ["a", "b", "Cell 3", "c"]
    eng = Engine(parse_program("seen(Y) <-0 link(X,Y)\n"), both)
    eng.run(2)
    final = eng.interpretation()
    assert final["seen(c)"] == (1.0, 1.0) and final['infected("Cell 3")'] == (0.5, 1.0)
    assert final["alarm(b)"] == (0.6, 0.8)  # set at t = 1 (the window 1..3)
    assert eng.fact(3).static and not eng.fact(0).static


def facts_of_with_windows(g: Graph) -> list[tuple]:
    return [(f.literal.pred, tuple(t.name for t in f.literal.args), round(f.literal.lower, 9),
             round(f.literal.upper, 9), f.start, f.end, f.static) for f in g.facts]


@pytest.mark.parametrize("body,fragment", [
    ("atom\nlink(a\n", "row 1: atom 'link(a' is not a ground literal"),
    ('atom\n"link(X,b)"\n', "row 1: atom 'link(X,b)' names a variable"),
    ("atom,lower\np(a),0.5\np(b),1.5\n", "row 2: bound [1.5,1] of p(b) is not inside [0,1]"),
    ("atom,start,end\np(a),3,1\n", "row 1: window 3..1 of p(a)"),
    ("atom,start,end\np(a),0,1\np(b),0,2000000000\n", "row 2: window 0..2000000000 of p(b): times are at most"),
    ('atom\np(a)\n"p(a,b)"\n', "predicate 'p' is used with one and with two arguments"),
    ("name\np(a)\n", "a fact table needs an 'atom' column"),
])
def test_bad_fact_tables_name_the_row(tmp_path: Path, body: str, fragment: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(ProgramCheckError, match=re.escape(fragment)) as e:
        load_fact_table(path)
    assert e.value.file == str(path)


def test_reason_with_a_fact_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rules = tmp_path / "spread.rules"
    rules.write_text("infected(X) <-1 infected(Y), link(Y,X)\n")
    table = tmp_path / "facts.csv"
    table.write_text('atom\ninfected(a)\n"link(a,b)"\n"link(b,c)"\n')
    assert cli_main(["reason", str(rules), "--facts-table", str(table), "--steps", "3", "--no-trace"]) == 0
    out, err = capsys.readouterr()
    assert "never set" not in err and "infected(c): [1,1]" in out


def test_queries_in_the_api_and_reason(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rules = tmp_path / "spread.rules"
    rules.write_text("infected(X) <-1 infected(Y), link(Y,X)\ninfected(a)\nlink(a,b)\nlink(b,\"C d\")\n"
                     "link(b,b)\nrisk(b):[0.2,0.6]\n")
    eng = Engine(load_program(rules))
    eng.run(3)
    assert eng.match("infected(X)") == [({"X": "a"}, (1.0, 1.0)), ({"X": "b"}, (1.0, 1.0)),
                                        ({"X": "C d"}, (1.0, 1.0))]
    assert eng.match("link(b,Y)") == [({"Y": "C d"}, (1.0, 1.0)), ({"Y": "b"}, (1.0, 1.0))]
    assert eng.match("link(X,X)") == [({"X": "b"}, (1.0, 1.0))]
    assert eng.match("risk(X)") == []  # [0.2,0.6] is not inside [1,1]
    assert eng.match("risk(X):[0,0.7]") == [({"X": "b"}, (0.2, 0.6))]
    assert eng.match("~risk(X):[0.4,0.8]") == [({"X": "b"}, (0.2, 0.6))]
    assert eng.match("nosuch(X)") == [] and eng.match("link(X)") == []
    assert cli_main(["reason", str(rules), "--steps", "3", "--query", "infected(X)", "--query-at", "each"]) == 0
    out = capsys.readouterr().out
    assert "t=0 infected(X): 1 answer\n  X=a  [1,1]\n" in out
    assert 't=2 infected(X): 3 answers\n  X=a  [1,1]\n  X=b  [1,1]\n  X="C d"  [1,1]\n' in out
    assert cli_main(["reason", str(rules), "--steps", "2", "--query", "infected(X)", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)["queries"]
    assert got == [{"t": 1, "query": "infected(X)", "bindings": {"X": x}, "bound": [1.0, 1.0]} for x in "ab"]
    assert cli_main(["reason", str(rules), "--steps", "1", "--query", "infected(X"]) == 1
    assert capsys.readouterr().err.startswith("tracelab: error: --query 'infected(X': ")


def test_scanner_node_ids_short_long_and_unicode(tmp_path: Path) -> None:
    # the scanner's table keeps ids of up to 7 bytes in the slot itself and checks longer ones against
    # its byte pool: ids around that length, sharing prefixes, and multi-byte UTF-8 must all stay apart
    ids = ["a", "ab", "abcdefg", "abcdefgh", "abcdefgi", "abcdefg1", "x" * 40, "x" * 41, "zelle-ü", "zelle-üb",
           "n1", "n10", "n100", "1", "01"]
    rng = np.random.default_rng(5)
    g = nx.DiGraph()
    for i, n in enumerate(ids):
        g.add_node(n, hp=i / 20)
    for _ in range(300):
        u, v = (ids[int(k)] for k in rng.integers(0, len(ids), 2))
        g.add_edge(u, v, link=True)
    fast, full = _both_readers(write(tmp_path, g))
    _same_graph(fast, full)
    assert fast.nodes[:len(ids)] == ids


def test_a_node_id_with_a_line_break_is_still_named(tmp_path: Path) -> None:
    path = tmp_path / "nl.graphml"  # &#10; is a line break in an attribute value (a written one is a space)
    path.write_text('<graphml><key id="k" for="node" attr.name="hp" attr.type="double"/><graph>'
                    '<node id="ok"/><node id="two&#10;lines"><data key="k">0.5</data></node></graph></graphml>')
    with pytest.raises(ProgramCheckError, match="node id 'two\\\\nlines' cannot be a constant.*line break"):
        load_graphml(path)
