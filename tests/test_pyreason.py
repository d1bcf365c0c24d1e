"""PyReason programs as they are (docs/pyreason.md): PyReason's rule, fact and GraphML formats read and
translated, checked on PyReason's documented examples; convert-pyreason's round trip; the rule trace in
PyReason's CSV layout; located errors.

The example inputs in tests/data/pyreason were written for these tests from the descriptions in PyReason's
docs; the expected figures are copied from the docs' "Expected Output" sections (cited per test).
Tests that need features of the shared issue-14 syntax (quantifiers, annotation functions, set_static,
infer_edges) skip, detected at run time, while this tracelab's parser does not read them."""
from __future__ import annotations

import csv
import json
import random
import subprocess
import sys
from pathlib import Path

import pytest
from located import assert_located
from tracelab.engine import Engine, ProgramError, load_graphml, parse_program
from tracelab.engine.graph import read_raw_graphml
from tracelab.engine.program import SourceLoc

from tracelab.cli import main
from tracelab.pyreason import graphml, load_pyreason
from tracelab.pyreason.graphml import attribute_fact
from tracelab.pyreason.graphml_columns import numeric_facts
from tracelab.pyreason.names import NameMap
from tracelab.pyreason.rules import Threshold, parse_rule, read_rules
from tracelab.pyreason.translate import rule_text, threshold_text

DATA = Path(__file__).resolve().parent / "data" / "pyreason"
HELLO = {"rule_files": [DATA / "hello_rules.txt"], "fact_files": [DATA / "hello_facts.csv"],
            "graph_file": DATA / "friends_graph.graphml"}
VIEWED = {"rule_files": [DATA / "viewed_rules.json"], "fact_files": [DATA / "viewed_facts.csv"],
             "graph_file": DATA / "group_chat.graphml"}


def parser_reads(text: str) -> bool:
    """Whether this tracelab's rule parser reads `text` (a feature of the shared issue-14 syntax)."""
    try:
        parse_program(text)
    except ProgramError:
        return False
    return True


QUANTIFIERS = parser_reads("e(a,b)\np(b)\nh(X) <-0 e(X,Y), [>= 50%] p(Y)\n")
ANNOTATION_FUNCTIONS = parser_reads("p(a)\nh(X):average <-0 p(X)\n")
SET_STATIC = parser_reads("p(a)\nh(X) <-0 p(X) {set_static}\n")
INFER_EDGES = parser_reads("p(a)\nq(b)\nh(X,Y) <-0 p(X), q(Y) {infer_edges}\n")


def labelled(engine: Engine, pred: str) -> dict[str, tuple[float, float]]:
    """Every `pred` atom the engine knows whose bound is not [0,1] (what PyReason's filter prints)."""
    out = {}
    for binding, bound in engine.match(f"{pred}(X):[0,1]"):
        if tuple(bound) != (0.0, 1.0):
            out[binding["X"]] = tuple(bound)
    return out


def run_steps(translated, steps: int, pred: str) -> list[dict[str, tuple[float, float]]]:
    engine = Engine(translated.program, translated.graph)
    out = []
    for _ in range(steps):
        engine.step()
        out.append(labelled(engine, translated.names.predicate(pred)))
    return out


# ------------------------------------------------------------------------------- documented examples

# PyReason docs, docs/source/tutorials/basic_tutorial.rst (also docs/hello-world.md), "Expected Output"
# of `pr.reason(timesteps=2)`: the `popular` column per timestep.
HELLO_EXPECTED = [
    {"Mary": (1.0, 1.0)},
    {"Mary": (1.0, 1.0), "Justin": (1.0, 1.0)},
    {"Mary": (1.0, 1.0), "Justin": (1.0, 1.0), "John": (1.0, 1.0)},
]


def test_hello_world_gives_pyreasons_documented_output() -> None:
    translated = load_pyreason(**HELLO)
    assert run_steps(translated, 3, "popular") == HELLO_EXPECTED


# PyReason docs, docs/source/tutorials/custom_thresholds.rst, "Expected output" of `pr.reason(timesteps=3)`:
# the ViewedByAll column per timestep (empty at 0 and 1, TextMessage [1.0, 1.0] at 2 and 3).
VIEWED_EXPECTED = [{}, {}, {"TextMessage": (1.0, 1.0)}, {"TextMessage": (1.0, 1.0)}]


def test_threshold_example_translates_to_a_quantifier() -> None:
    rule = read_rules(DATA / "viewed_rules.json")[0]
    assert rule_text(rule, NameMap()) == \
        "viewed_by_all_rule: viewedByAll(Y) <-0 haveAccess(X,Y), [>= 100%] viewed(X)"


@pytest.mark.skipif(not QUANTIFIERS, reason="needs quantifiers ([>= 100%] clauses) in the rule parser")
def test_threshold_example_gives_pyreasons_documented_output() -> None:
    translated = load_pyreason(**VIEWED)
    assert run_steps(translated, 4, "ViewedByAll") == VIEWED_EXPECTED


# ------------------------------------------------------------------------------------ the rule format

def _rule(text: str, **opts) -> str:
    r = parse_rule(text, "r", SourceLoc("rules.txt", 1, 1))
    for k, v in opts.items():
        setattr(r, k, v)
    return rule_text(r, NameMap())


@pytest.mark.parametrize("pyreason, tracelab", [
    ("popular(x) : [1,1] <-1 popular(y) : [1,1] , Friends(x,y) : [1,1]",
     "r: popular(X) <-1 popular(Y), friends(X,Y)"),
    ("a(x) <- b(x):True, c(x):false", "r: a(X) <-0 b(X), c(X):[0,0]"),
    ("a(x):False <-2 ~b(x), ~c(x):[0.2,0.7]", "r: a(X):[0,0] <-2 b(X):[0,0], c(X):[.3,.8]"),
    ("~a(x) <-0 b(x)", "r: a(X):[0,0] <-0 b(X)"),
    ("~a(x):[0,0.25] <-0 b(x)", "r: a(X):[.75,1] <-0 b(X)"),
    ("Is.Part-of(a1,b_2) <-0 has.part(b_2,a1)", "r: is_Part_of(A1,B_2) <-0 has_part(B_2,A1)"),
    ("h(x) <-1 e(x,y), forall(p(y))", "r: h(X) <-1 e(X,Y), [forall] p(Y)"),
    ("risk(x):average <-1 exposed(x,y), risk(y):[0,1]", "r: risk(X):average <-1 exposed(X,Y), risk(Y):[0,1]"),
    ("m(x):maximum <-0 a(x)", "r: m(X):max <-0 a(X)"),
    ("m(x):my_fn <-0 a(x)", "r: m(X):my_fn <-0 a(X)"),
])
def test_rule_text_translation(pyreason: str, tracelab: str) -> None:
    assert _rule(pyreason) == tracelab


def test_rule_options_translate_to_the_shared_syntax() -> None:
    assert _rule("c(x,y) <-0 p(x), q(y)", set_static=True, infer_edges=True) == \
        "r: c(X,Y) <-0 p(X), q(Y) {set_static, infer_edges}"
    assert _rule("c(x) <-0 p(x)", infer_edges=True) == "r: c(X) <-0 p(X)"  # PyReason ignores it on node rules
    assert _rule("s(x):average <-0 p(x), q(x)", weights=[1.0, 2.0]) == \
        "r: s(X):weighted_average <-0 p(X), q(X) {weights=1,2}"
    assert _rule("s(x):average <-0 p(x), q(x)", weights=[2.0, 2.0]) == "r: s(X):average <-0 p(X), q(X)"
    assert _rule("s(x):mine <-0 p(x), q(x)", weights=[2.0, 2.0]) == "r: s(X):mine <-0 p(X), q(X) {weights=2,2}"


@pytest.mark.parametrize("threshold, text", [
    (Threshold("greater_equal", "number", "total", 1), ""),
    (Threshold("greater_equal", "percent", "total", 50), "[>= 50%] "),
    (Threshold("greater", "number", "available", 2), "[> 2 available] "),
    (Threshold("less_equal", "percent", "available", 12.5), "[<= 12.5% available] "),
    (Threshold("less", "number", "total", 3), "[< 3] "),
    (Threshold("equal", "number", "total", 0), "[== 0] "),
])
def test_thresholds_translate_to_quantifiers(threshold: Threshold, text: str) -> None:
    assert threshold_text(threshold, forall=False) == text


def test_json_rules_carry_thresholds_options_and_weights(tmp_path: Path) -> None:
    f = tmp_path / "rules.json"
    f.write_text(json.dumps([
        {"rule_text": "ally(a, b) <- friend(a, b), common(a, b)", "name": "ally", "set_static": True,
         "infer_edges": "yes",
         "custom_thresholds": {"1": {"quantifier": "less", "quantifier_type": ["percent", "available"],
                                     "thresh": 30}}},
        {"rule_text": "s(x):average <- p(x), q(x)", "weights": [1, 3]},
    ], indent=1))
    names = NameMap()
    texts = [rule_text(r, names) for r in read_rules(f)]
    assert texts == ["ally: ally(A,B) <-0 friend(A,B), [< 30% available] common(A,B) {set_static, infer_edges}",
                     "rule_1: s(X):weighted_average <-0 p(X), q(X) {weights=1,3}"]


def test_csv_rules_and_facts(tmp_path: Path) -> None:
    (tmp_path / "r.csv").write_text('rule_text,name,infer_edges,set_static\n'
                                    '"a(x) <-1 b(x), c(x)",first,False,no\n'
                                    'd(x) <- a(x),,,\n')
    (tmp_path / "f.csv").write_text('b(n1),,0,3\n"c(n1):[1,1]",cfact,0,3,false\n"e(n1,n2) : [0.5, 1]",edge,1,1\n'
                                    'x(n1),,,,true\n')
    t = load_pyreason([tmp_path / "r.csv"], [tmp_path / "f.csv"], persistent=True).text
    assert t.splitlines()[1:] == ["first: a(X) <-1 b(X), c(X)", "rule_1: d(X) <-0 a(X)", "fact_0: b(n1) @0..3",
                                  "cfact: c(n1) @0..3", "edge: e(n1,n2):[.5,1] @1", "fact_3: x(n1) static"]


def test_predicate_names_that_clash_stay_apart() -> None:
    names = NameMap()
    assert [names.predicate(n) for n in ("Friends", "friends", "Friends", "a-b", "a_b")] == \
        ["friends", "friends_2", "friends", "a_b", "a_b_2"]
    assert names.original_predicate("friends_2") == "friends"


# ------------------------------------------------------------------------------------ the graph mapping

@pytest.mark.parametrize("value, fact", [
    (1, ("k", 1.0, 1.0)), (0.75, ("k", 0.75, 1.0)), (0, ("k", 0.0, 1.0)), (True, ("k", 1.0, 1.0)),
    (False, ("k", 0.0, 1.0)), (5, ("k-5", 1.0, 1.0)), (2.5, ("k-2.5", 1.0, 1.0)), ("0.3", ("k", 0.3, 1.0)),
    ("0,1", ("k", 0.0, 1.0)), ("red", ("k-red", 1.0, 1.0)), ("0.5,1", ("k-0.5,1", 1.0, 1.0)),
])
def test_graph_attributes_map_as_in_pyreason(value: object, fact: tuple) -> None:
    assert attribute_fact("k", value) == fact


def test_graphml_reads_with_pyreasons_mapping(tmp_path: Path) -> None:
    g = tmp_path / "g.graphml"
    g.write_text('<?xml version="1.0"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n'
                 '<key id="h" for="node" attr.name="health" attr.type="double"/>\n'
                 '<key id="c" for="node" attr.name="color" attr.type="string"/>\n'
                 '<key id="w" for="edge" attr.name="Near" attr.type="boolean"/>\n'
                 '<graph edgedefault="undirected">\n'
                 '<node id="a"><data key="h">0.75</data><data key="c">red</data></node>\n'
                 '<node id="B"/>\n'
                 '<edge source="a" target="B"><data key="w">true</data></edge>\n'
                 '</graph></graphml>\n')
    (tmp_path / "r.txt").write_text("ok(x) <-0 health(x):[0.5,1], color-red(x), Near(x,y)\n")
    t = load_pyreason([tmp_path / "r.txt"], [], g, embed_graph=True).text
    lines = t.splitlines()
    assert lines[2] == "rule_0: ok(X) <-0 health(X):[.5,1], color_red(X), near(X,Y)"
    assert lines[3].startswith("# the graph's facts")
    assert lines[4:] == ["health(a):[.75,1] static", "color_red(a) static", 'near(a,"B") static', 'near("B",a) static']
    translated = load_pyreason([tmp_path / "r.txt"], [], g)
    engine = Engine(translated.program, translated.graph)
    engine.step()
    assert labelled(engine, "ok") == {"a": (1.0, 1.0)}


def _random_graphml(path: Path, seed: int, undirected: bool) -> None:
    """Numeric and boolean attributes in [0,1], parallel edges, self-loops, a key repeated on an element,
    edges without data and edge ends that are no <node>."""
    rng = random.Random(seed)
    keys = [("a", "node", "double"), ("b", "node", "boolean"), ("W", "edge", "long"), ("c", "edge", "float"),
            ("on", "edge", "boolean")]
    out = ['<?xml version="1.0"?>', '<graphml xmlns="http://graphml.graphdrawing.org/xmlns">']
    out += [f'<key id="k{i}" for="{f}" attr.name="{n}" attr.type="{t}"/>' for i, (n, f, t) in enumerate(keys)]
    out.append(f'<graph edgedefault="{"undirected" if undirected else "directed"}">')

    def data(domain: str) -> str:
        picks = [i for i, k in enumerate(keys) if k[1] == domain]
        parts = []
        for _ in range(rng.randrange(4)):
            i = rng.choice(picks)
            value = rng.choice(["true", "false", "1", "0"]) if keys[i][2] == "boolean" else \
                rng.choice(["0", "1"]) if keys[i][2] == "long" else f"{rng.random():.3f}"
            parts.append(f'<data key="k{i}">{value}</data>')
        return "".join(parts)
    out += [f'<node id="n{i}">{data("node")}</node>' for i in range(12)]
    out += [f'<edge source="n{rng.randrange(14)}" target="n{rng.randrange(14)}">{data("edge")}</edge>'
            for _ in range(60)]
    out.append("</graph></graphml>")
    path.write_text("\n".join(out))


@pytest.mark.parametrize("seed", range(6))
def test_array_mapping_equals_networkx_reading(tmp_path: Path, seed: int) -> None:
    g = tmp_path / "g.graphml"
    _random_graphml(g, seed, undirected=seed % 2 == 1)
    raw = read_raw_graphml(g)
    fast, slow = numeric_facts(raw), graphml._python_facts(raw)
    assert fast is not None

    def facts(f) -> list[tuple]:
        return [(f.labels[lab], *args, *bounds) for lab, args, bounds in
                zip(f.label_array().tolist(), f.args_array().tolist(), f.bounds_array().tolist())]
    assert facts(fast) == facts(slow)
    assert len(facts(fast)) > 20


def test_a_bad_graph_value_is_located(tmp_path: Path) -> None:
    g = tmp_path / "g.graphml"
    g.write_text('<?xml version="1.0"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n'
                 '<key id="b" for="node" attr.name="ok" attr.type="boolean"/>\n<graph edgedefault="directed">\n'
                 '<node id="a"><data key="b">maybe</data></node>\n</graph></graphml>\n')
    with pytest.raises(ProgramError) as e:
        load_pyreason([DATA / "hello_rules.txt"], [], g)
    assert (e.value.file, e.value.line) == (str(g), 5) and "'maybe' is not a boolean" in e.value.message


def test_an_undeclared_data_key_is_refused_at_its_first_use_by_both_readings(tmp_path: Path) -> None:
    g = tmp_path / "g.graphml"
    g.write_text('<?xml version="1.0"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n'
                 '<key id="b" for="node" attr.name="ok" attr.type="boolean"/>\n<graph edgedefault="directed">\n'
                 '<node id="a"><data key="b">true</data></node>\n'
                 '<node id="c"><data key="zz">true</data></node>\n</graph></graphml>\n')
    for read in (lambda: graphml.load_pyreason_graphml(g, NameMap()), lambda: load_graphml(g)):
        with pytest.raises(ProgramError) as e:
            read()
        assert_located(e.value, str(g), 6, 14, '<data key="zz"> names no <key>')


def test_other_values_take_the_value_by_value_reading(tmp_path: Path) -> None:
    g = tmp_path / "g.graphml"
    _random_graphml(g, 0, undirected=False)
    g.write_text(g.read_text().replace('attr.type="long"', 'attr.type="string"'))
    assert numeric_facts(read_raw_graphml(g)) is None


# ---------------------------------------------------------------------- features of the shared syntax

@pytest.mark.skipif(not SET_STATIC, reason="needs the {set_static} rule option in the rule parser")
def test_set_static_freezes_the_head(tmp_path: Path) -> None:
    (tmp_path / "r.csv").write_text("a(x) <-0 b(x),keep,False,True\n")
    (tmp_path / "f.csv").write_text("b(n),,0,0\n")
    got = run_steps(load_pyreason([tmp_path / "r.csv"], [tmp_path / "f.csv"]), 2, "a")
    assert got == [{"n": (1.0, 1.0)}, {"n": (1.0, 1.0)}]  # not reset at t=1: static once the rule fired


@pytest.mark.skipif(not INFER_EDGES, reason="needs the {infer_edges} rule option in the rule parser")
def test_infer_edges_creates_the_edge(tmp_path: Path) -> None:
    (tmp_path / "r.csv").write_text('"link(x,y) <-0 p(x), q(y)",inferred,True,False\n')
    (tmp_path / "f.csv").write_text("p(a),,0,0\nq(b),,0,0\n")
    translated = load_pyreason([tmp_path / "r.csv"], [tmp_path / "f.csv"])
    engine = Engine(translated.program, translated.graph)
    engine.step()
    assert [(b, tuple(v)) for b, v in engine.match("link(X,Y)")] == [({"X": "a", "Y": "b"}, (1.0, 1.0))]


LINE_GRAPH = """<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
  <key id="f" for="edge" attr.name="Friends" attr.type="long"/>
  <graph edgedefault="directed">
    <node id="a"/><node id="b"/><node id="c"/>
    <edge source="a" target="b"><data key="f">1</data></edge>
    <edge source="b" target="c"><data key="f">1</data></edge>
  </graph>
</graphml>
"""


@pytest.mark.skipif(not INFER_EDGES, reason="needs the {infer_edges} rule option in the rule parser")
def test_edge_rules_set_only_the_graphs_edges_unless_they_infer_edges(tmp_path: Path) -> None:
    # PyReason grounds an edge rule's head on the graph's edges; only infer_edges=True adds new ones
    (tmp_path / "g.graphml").write_text(LINE_GRAPH)
    (tmp_path / "r.csv").write_text('"near(x,z) <-0 Friends(x,y), Friends(y,z)",near,False,False\n'
                                    '"far(x,z) <-0 Friends(x,y), Friends(y,z)",far,True,False\n'
                                    '"fof(x,y) <-0 Friends(x,y)",fof,False,False\n')
    translated = load_pyreason([tmp_path / "r.csv"], graph_file=tmp_path / "g.graphml")
    assert "%edge_heads graph" in translated.text
    engine = Engine(translated.program, translated.graph)
    engine.step()

    def pairs(pred: str) -> set[tuple[str, str]]:
        return {(b["X"], b["Y"]) for b, v in engine.match(f"{pred}(X,Y)")}
    assert pairs("near") == set()                  # a->c is no edge of the graph
    assert pairs("far") == {("a", "c")}            # infer_edges: the rule makes the edge
    assert pairs("fof") == {("a", "b"), ("b", "c")}
    # embedded in the text (convert-pyreason --graph), the graph's edges are lost, and the text says so
    embedded = load_pyreason([tmp_path / "r.csv"], graph_file=tmp_path / "g.graphml", embed_graph=True)
    assert "%edge_heads graph" not in embedded.text and "not restricted" in embedded.text


@pytest.mark.skipif(not ANNOTATION_FUNCTIONS, reason="needs annotation functions (p(X):average) in the parser")
def test_average_annotation_function(tmp_path: Path) -> None:
    (tmp_path / "r.txt").write_text("h(x):average <-0 a(x):[0.1,1], b(x):[0.1,1]\n")
    (tmp_path / "f.csv").write_text('"a(n):[0.2,1]",,0,0\n"b(n):[0.4,1]",,0,0\n')
    got = run_steps(load_pyreason([tmp_path / "r.txt"], [tmp_path / "f.csv"]), 1, "h")
    assert got[0]["n"] == pytest.approx((0.3, 1.0))


# ------------------------------------------------------------------------------------------ errors

@pytest.mark.parametrize("line, col, needle", [
    ("popular(x) <-1 popular(y), Friends(x,y", 39, "missing ')'"),
    ("popular(x) popular(y)", 22, "expected '<-'"),
    ("p(x) <-1 q(x) <-2 r(x)", 15, "one '<-'"),
    ("p(x) <-1 q(x), , r(x)", 16, "empty body clause"),
    ("p(x) <-1 q(x):[0.5,1.5]", 20, "outside [0,1]"),
    ("p(x) <-1 q(x):[0.9, 0.5]", 15, "greater than"),
    ("p(x) <-1 q(x) > 3", 15, "comparison clauses"),
    ("p(x) <-1 q(f(x))", 13, "head functions are only allowed in a rule head"),
    ("p(x) <-1 q(x), 1q(x)", 16, "not a predicate name"),
    ("p(x) <-1 q(x,y,z)", 12, "3 arguments"),
    ("p(x) <-1", 9, "without a body"),
    ("p(x) <-1 ~~q(x)", 10, "double negation"),
])
def test_bad_rules_name_file_line_and_column(tmp_path: Path, line: str, col: int, needle: str) -> None:
    f = tmp_path / "rules.txt"
    f.write_text("# a comment\n\n" + line + "\n")
    with pytest.raises(ProgramError) as e:
        load_pyreason([f])
    assert_located(e.value, str(f), 3, col, needle)


def test_engine_checks_point_back_at_the_pyreason_file(tmp_path: Path) -> None:
    f = tmp_path / "rules.txt"
    f.write_text("p(x) <-1 q(x)\np(x) <-1 q(x):[0,1]\n")  # x is unsafe: [0,1] binds nothing
    with pytest.raises(ProgramError) as e:
        load_pyreason([f])
    assert (e.value.file, e.value.line) == (str(f), 2) and "in its translation" in e.value.message


def test_bad_fact_files_are_located(tmp_path: Path) -> None:
    f = tmp_path / "facts.csv"
    f.write_text("fact_text,name,start_time,end_time,static\np(a),ok,0,1\np(b),late,3,x\n")
    with pytest.raises(ProgramError) as e:
        load_pyreason([DATA / "hello_rules.txt"], [f])
    assert (e.value.line, e.value.column) == (3, 13) and "end_time 'x'" in e.value.message
    j = tmp_path / "facts.json"
    j.write_text('[\n {"fact_text": "p(a)"},\n {"fact_text": "p(b):[1,0]", "start_time": 1}\n]\n')
    with pytest.raises(ProgramError) as e:
        load_pyreason([DATA / "hello_rules.txt"], [j])
    assert (e.value.line, e.value.column) == (3, 22) and "greater than" in e.value.message


def test_bad_json_threshold_is_located(tmp_path: Path) -> None:
    f = tmp_path / "rules.json"
    f.write_text('[\n {"rule_text": "a(x) <- b(x,y), c(y)",\n  "custom_thresholds": [{"quantifier": "most", '
                 '"quantifier_type": ["number", "total"], "thresh": 1}, {}]}\n]\n')
    with pytest.raises(ProgramError) as e:
        load_pyreason([f])
    assert (e.value.line, e.value.column) == (2, 17) and "not valid" in e.value.message


# ------------------------------------------------------------------------------- the command line

@pytest.mark.parametrize("example, query, expected", [
    pytest.param(HELLO, "popular(X)", HELLO_EXPECTED, id="hello-world"),
    pytest.param(VIEWED, "viewedByAll(X)", VIEWED_EXPECTED, id="threshold", marks=pytest.mark.skipif(
        not QUANTIFIERS, reason="needs quantifiers ([>= 100%] clauses) in the rule parser")),
])
def test_convert_round_trip_gives_the_same_result(tmp_path: Path, capsys: pytest.CaptureFixture, example: dict,
                                                  query: str, expected: list) -> None:
    out = tmp_path / "converted.rules"
    files = [*map(str, example["rule_files"]), *(a for f in example["fact_files"] for a in ("--facts", str(f))),
             "--graph", str(example["graph_file"])]
    assert main(["convert-pyreason", *files, "-o", str(out)]) == 0
    capsys.readouterr()
    runs = []
    steps = str(len(expected))
    for argv in (["reason", str(out)], ["reason", "--dialect", "pyreason", *files]):
        assert main([*argv, "--steps", steps, "--json", "--query", query, "--query-at", "each"]) == 0
        runs.append(json.loads(capsys.readouterr().out))
    assert runs[0]["queries"] == runs[1]["queries"]
    assert runs[0]["interpretation"] == runs[1]["interpretation"]
    per_step = [sorted(q["bindings"]["X"] for q in runs[0]["queries"] if q["t"] == t) for t in range(len(expected))]
    assert per_step == [sorted(e) for e in expected]


def test_pyreason_trace_csv_layout(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["reason", "--dialect", "pyreason", str(DATA / "hello_rules.txt"), "--facts",
                 str(DATA / "hello_facts.csv"), "--graph", str(DATA / "friends_graph.graphml"), "--steps", "3",
                 "--no-trace", "--pyreason-trace", str(tmp_path / "out")]) == 0
    nodes, = (tmp_path / "out").glob("rule_trace_nodes_*.csv")
    edges, = (tmp_path / "out").glob("rule_trace_edges_*.csv")
    assert nodes.name[len("rule_trace_nodes_"):] == edges.name[len("rule_trace_edges_"):]
    rows = list(csv.reader(nodes.open()))
    assert rows[0] == ["Time", "Fixed-Point-Operation", "Node", "Label", "Old Bound", "New Bound",
                       "Occurred Due To", "Consistent", "Triggered By", "Inconsistency Message",
                       "Clause-1", "Clause-2", "Clause-3", "Clause-4"]
    # the graph's own facts and the resets are no rows (PyReason's defaults); Mary's fact is re-applied
    # each step, as in PyReason's example trace (examples/csv_outputs/basic_rule_trace_nodes_*.csv), in
    # its order: John (node 0 of the graph) before Justin (node 2) at t = 2
    assert [r[:4] + r[5:6] for r in rows[1:]] == [
        ["0", "0", "Mary", "popular", "[1.0,1.0]"], ["1", "1", "Mary", "popular", "[1.0,1.0]"],
        ["1", "1", "Justin", "popular", "[1.0,1.0]"], ["2", "2", "Mary", "popular", "[1.0,1.0]"],
        ["2", "2", "John", "popular", "[1.0,1.0]"], ["2", "2", "Justin", "popular", "[1.0,1.0]"]]
    assert rows[1][4:] == ["[0.0,1.0]", "[1.0,1.0]", "popular_fact", "True", "Fact", "", "", "", "", ""]
    assert rows[3][4:] == ["[0.0,1.0]", "[1.0,1.0]", "rule_0", "True", "Rule", "", "['Mary']",
                           "[('Justin', 'Mary')]", "[('Mary', 'Cat')]", "[('Justin', 'Cat')]"]
    assert edges.read_text().splitlines() == [",".join(rows[0][:10]).replace("Node", "Edge")]


def test_pyreason_trace_marks_an_inconsistency(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "r.txt").write_text("q(x) <-0 p(x)\n")
    (tmp_path / "f.csv").write_text('"p(a):[0,0.2]",lo,0,1\n"p(a):[0.8,1]",hi,1,1\n')
    assert main(["reason", "--dialect", "pyreason", str(tmp_path / "r.txt"), "--facts", str(tmp_path / "f.csv"),
                 "--steps", "2", "--persistent", "--no-trace", "--pyreason-trace", str(tmp_path / "out")]) == 0
    nodes, = (tmp_path / "out").glob("rule_trace_nodes_*.csv")
    rows = list(csv.reader(nodes.open()))[1:]
    assert [r[:8] for r in rows] == [["0", "0", "a", "p", "[0.0,1.0]", "[0.0,0.2]", "lo", "True"],
                                     ["1", "1", "a", "p", "[0.0,0.2]", "[0.0,1.0]", "hi", "False"]]
    # the fact that met the other's bound is named, as PyReason names it (docs/pyreason.md)
    assert rows[1][9] == ("Inconsistency occurred. Conflicting bounds for p(a). Update from [0.000, 0.200] to "
                          "[0.800, 1.000] is not allowed. Setting bounds to [0,1] and static=True for this timestep.")


def test_pyreason_trace_writes_edges_as_tuples(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "r.txt").write_text("Knows(x,y) <-1 Friends(x,y), popular(y)\n")
    (tmp_path / "f.csv").write_text("popular(Mary),pop,0,0\n")
    assert main(["reason", "--dialect", "pyreason", str(tmp_path / "r.txt"), "--facts", str(tmp_path / "f.csv"),
                 "--graph", str(DATA / "friends_graph.graphml"), "--steps", "2", "--no-trace",
                 "--pyreason-trace", str(tmp_path / "out")]) == 0
    edges, = (tmp_path / "out").glob("rule_trace_edges_*.csv")
    rows = list(csv.reader(edges.open()))
    assert rows[0][2] == "Edge" and rows[0][10:] == ["Clause-1", "Clause-2"]
    # in grounding order (John is node 0 of the graph, Justin node 2)
    assert rows[1:] == [["1", "1", "('John', 'Mary')", "Knows", "[0.0,1.0]", "[1.0,1.0]", "rule_0", "True", "Rule",
                         "", "[('John', 'Mary')]", "['Mary']"],
                        ["1", "1", "('Justin', 'Mary')", "Knows", "[0.0,1.0]", "[1.0,1.0]", "rule_0", "True", "Rule",
                         "", "[('Justin', 'Mary')]", "['Mary']"]]


def test_a_pyreason_error_on_the_command_line_is_one_line(tmp_path: Path) -> None:
    f = tmp_path / "bad.txt"
    f.write_text("p(x) <-1 q(x\n")
    r = subprocess.run([sys.executable, "-m", "tracelab", "reason", "--dialect", "pyreason", str(f), "--steps", "1"],
                       capture_output=True, text=True, check=False)
    assert r.returncode == 1 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [f"tracelab: error: {f}:1:13: Failed to parse rule - missing ')' or ']'"]
