"""Hand-written cases for `%closed`, `{set_static}` and `{infer_edges}` / `%edge_heads graph`
(docs/language.md): the reference evaluator, the counting kernel and the lanes kernel give the values
worked out here by hand, and the parser's errors are located."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from located import assert_located
from tracelab.engine import Engine, load_graphml, parse_program
from tracelab.engine.errors import ProgramCheckError, RuleSyntaxError
from tracelab.engine.reference import ReferenceEvaluator, atom_text

from tracelab.store.reader import open_run, query_readonly
from tracelab.store.writer import TraceWriter

LANES_WORLDS = 64  # the lanes kernel takes a batch of 64 worlds; world 0 is compared


def run_all(text: str, steps: int, graph=None, lanes: bool = True) -> list[list[dict[str, tuple[float, float]]]]:
    """The interpretation after each step, from the reference, the counting and the lanes kernel (all
    three must agree; returns the reference's). lanes=False: a program the lanes refuse (quantifiers,
    annotation functions) runs on the reference and the counting kernel only."""
    program = parse_program(text, "<test>")
    edges = [] if graph is None else [(graph.nodes[a], graph.nodes[b]) for a, b in graph.edges.tolist()]
    ref = ReferenceEvaluator(program, graph.nodes if graph else (), graph.facts if graph else (),
                             graph_edges=edges)
    engines = [Engine(program, graph, kernel="counting")]
    if lanes:
        engines.append(Engine(program, graph, kernel="lanes", worlds=LANES_WORLDS))
    out = []
    for t in range(steps):
        ref.step()
        want = {atom_text(a): iv for a, iv in ref.interpretation().items()}
        for eng in engines:
            eng.step()
            assert eng.interpretation(0) == want, f"{eng.kernel} at t={t}"
        out.append(want)
    return out


def true_atoms(interp: dict[str, tuple[float, float]], pred: str) -> list[str]:
    return sorted(a for a, iv in interp.items() if a.startswith(pred + "(") and iv == (1.0, 1.0))


# ---- %closed --------------------------------------------------------------------------------------

CLOSED_NAF = """
%timesteps reset
q(a) @0..5
q(b) @0..5
p(a) @2
r(X) <-0 q(X), ~p(X)
"""


def test_closed_predicate_reads_unset_atoms_as_false() -> None:
    steps = run_all("%closed p\n" + CLOSED_NAF, 4)
    assert [true_atoms(s, "r") for s in steps] == [["r(a)", "r(b)"], ["r(a)", "r(b)"], ["r(b)"],
                                                    ["r(a)", "r(b)"]]


def test_open_predicate_complement_needs_the_atom_set_false() -> None:
    steps = run_all(CLOSED_NAF, 4)
    assert [true_atoms(s, "r") for s in steps] == [[], [], [], []]


def test_closed_clause_whose_bound_holds_of_false() -> None:
    # p(X):[0,0.5] holds of [0,0] and so of every unset atom of a closed p, but not of p(a) = [1,1]
    # nor of p(c) = [0.75,1]
    text = """%closed p
q(a)
q(b)
q(c)
p(a)
p(c):[0.75,1]
r(X) <-0 q(X), p(X):[0,0.5]
"""
    (s,) = run_all(text.replace("p(c):[0.75,1]\n", ""), 1)
    assert true_atoms(s, "r") == ["r(b)", "r(c)"]
    program = parse_program(text)
    eng = Engine(program)
    eng.step()
    assert set(true_atoms(eng.interpretation(), "r")) == {"r(b)"}


def test_closed_ground_rule_without_enumerating_clause() -> None:
    (s,) = run_all("%closed alarm\nquiet(base) <-0 ~alarm(base)\n", 1)
    assert s == {"quiet(base)": (1.0, 1.0)}


def test_closed_clause_alone_cannot_bind_a_variable() -> None:
    with pytest.raises(ProgramCheckError) as e:
        parse_program("%closed p\nq(a)\nr(X) <-0 q(a), ~p(X)\n", "x.rules")
    assert (e.value.line, e.value.column) == (3, 3)  # the head's X
    assert "unsafe variable 'X'" in e.value.message and "'p' is %closed" in e.value.message


@pytest.mark.parametrize("text,line,col,fragment", [
    ("%closed\n", 1, 8, "expected a predicate name after '%closed'"),
    ("%closed p q\n", 1, 11, "expected ',' or end of line after a predicate of %closed"),
    ("%closed p,\n", 1, 11, "expected a predicate name after '%closed'"),
    ("%closed Pred\n", 1, 9, "invalid predicate name 'Pred'"),
    ("%edge_heads edges\n", 1, 13, "unknown value 'edges' for %edge_heads (expected any | graph)"),
    ("h(X) <-0 a(X) {set_static, static}\n", 1, 28, "unknown rule option 'static'"),
])
def test_located_errors(text: str, line: int, col: int, fragment: str) -> None:
    with pytest.raises((RuleSyntaxError, ProgramCheckError)) as e:
        parse_program(text, "x.rules")
    assert_located(e.value, "x.rules", line, col, fragment)


def test_closed_directive_repeats_and_lists() -> None:
    program = parse_program("%closed p, q\n%closed r\n%closed p\n")
    assert program.closed == ("p", "q", "r")


# ---- {set_static} ---------------------------------------------------------------------------------

def test_set_static_freezes_the_head_once_the_rule_fires() -> None:
    # s(a) fires at t = 0 and is static: the [0,0] fact at t = 2 is ignored (without set_static the two
    # bounds conflict and reset_freeze leaves [0,1])
    text = "q(a)\nq(b)\ns(X) <-0 q(X) {OPT}\ns(a):[0,0] @2\n"
    frozen = run_all(text.replace("OPT", "set_static"), 3)
    plain = run_all(text.replace("OPT", "intersection"), 3)
    assert frozen[2]["s(a)"] == (1.0, 1.0)
    assert "s(a)" not in plain[2]  # [0,1]


def test_set_static_counts_ignored_updates_and_survives_reset() -> None:
    program = parse_program("%timesteps reset\nq(a) @0\ns(X) <-1 q(X) {set_static}\ns(a):[0,0] @2\n")
    for kernel, worlds in (("counting", 1), ("lanes", LANES_WORLDS)):
        eng = Engine(program, kernel=kernel, worlds=worlds)
        eng.run(4)
        a = eng.atom("s", "a")
        assert eng.bound(a) == (1.0, 1.0), kernel  # set at t = 1, static: the reset and the fact pass it by
        assert bool(eng.static[0, a]), kernel
        assert int(eng.stats["static_ignored"][0]) == 1, kernel


def test_immediate_set_static_freezes_even_without_a_change() -> None:
    # s(a) is already [1,1] from the fact when the immediate rule fires: the firing only freezes it
    text = "q(a) @0..3\ns(a) @0\ns(X) <-! q(X) {set_static}\ns(a):[0,0] @1\n"
    steps = run_all(text, 2)
    assert steps[1]["s(a)"] == (1.0, 1.0)
    eng = Engine(parse_program(text))
    eng.run(2)
    assert int(eng.stats["rederivations"][0]) >= 1 and int(eng.stats["static_ignored"][0]) == 1


# ---- {infer_edges} and %edge_heads graph ----------------------------------------------------------

GRAPHML = """<?xml version="1.0" encoding="UTF-8"?>
<graphml xmlns="http://graphml.graphdrawing.org/xmlns">
  <key id="w" for="node" attr.name="person" attr.type="boolean"/>
  <graph edgedefault="directed">
    <node id="a"><data key="w">true</data></node>
    <node id="b"><data key="w">true</data></node>
    <node id="c"><data key="w">true</data></node>
    <edge source="a" target="b"/>
    <edge source="b" target="c" directed="false"/>
  </graph>
</graphml>
"""

EDGE_RULES = """
knows(X,Y) <-0 person(X), person(Y), likes(X,Y)
met(X,Y) <-0 person(X), person(Y), likes(X,Y) {infer_edges}
likes(a,b)
likes(a,c)
likes(c,b)
"""


@pytest.fixture
def graph(tmp_path: Path):
    p = tmp_path / "g.graphml"
    p.write_text(GRAPHML)
    return load_graphml(p)


def test_graph_edges_both_ways_for_undirected(graph) -> None:
    pairs = {(graph.nodes[a], graph.nodes[b]) for a, b in graph.edges.tolist()}
    assert pairs == {("a", "b"), ("b", "c"), ("c", "b")}


def test_edge_heads_graph_keeps_rules_without_infer_edges_on_edges(graph) -> None:
    (s,) = run_all("%edge_heads graph\n" + EDGE_RULES, 1, graph)
    assert true_atoms(s, "knows") == ["knows(a,b)", "knows(c,b)"]  # (a,c) is no edge; (c,b) is (undirected)
    assert true_atoms(s, "met") == ["met(a,b)", "met(a,c)", "met(c,b)"]


def test_edge_heads_any_is_the_default(graph) -> None:
    (s,) = run_all(EDGE_RULES, 1, graph)
    assert true_atoms(s, "knows") == ["knows(a,b)", "knows(a,c)", "knows(c,b)"]


def test_edge_heads_graph_without_a_graph_has_no_edges() -> None:
    (s,) = run_all("%edge_heads graph\nq(a)\nlink(X,X) <-0 q(X)\nown(X,X) <-0 q(X) {infer_edges}\n", 1)
    assert true_atoms(s, "link") == [] and true_atoms(s, "own") == ["own(a,a)"]


def test_inferred_edges_on_new_nodes_reach_the_store(tmp_path: Path) -> None:
    """An edge inferred at t = 2 on a node first met then (an external fact) is a new atom: the run's atom
    table names it and its change row points at it."""
    program = parse_program("%edge_heads graph\nhub(h)\nlinked(X,Y) <-0 hub(X), joins(Y) {infer_edges}\n"
                            "joins(h):[0,0]\n")
    eng = Engine(program)
    meta = {"command": "pytest infer_edges", "scenario": "none", "rule_files": [], "seed": 0, "config": {}}
    with TraceWriter(tmp_path / "run", meta) as w:
        w.write_engine_program(eng)
        w.begin_episode(1, world=0, t_start=0, seed=0)
        for t in range(4):
            if t == 2:
                eng.add_fact(eng.atom("joins", "newcomer"))
            eng.step()
            w.write_engine(np.array([1]), eng)
        w.end_episode(1, steps=4, outcome="win", reward=0.0, rewards={}, t_end=3)
    con = open_run(tmp_path / "run")
    rows = query_readonly(con, "SELECT t, atom, rule FROM changes WHERE label = 'linked' ORDER BY t").fetchall()
    assert rows == [(2, "linked(h,newcomer)", "rule3")]
    atoms = query_readonly(con, "SELECT text FROM atoms WHERE arg1 = 'newcomer'").fetchall()
    assert atoms == [("linked(h,newcomer)",)]


def test_reason_cli_keeps_edge_heads_on_the_graph(graph, tmp_path: Path) -> None:
    rules = tmp_path / "edges.rules"
    rules.write_text("%edge_heads graph\n" + EDGE_RULES)
    (tmp_path / "g.graphml").write_text(GRAPHML)
    out = subprocess.run([sys.executable, "-m", "tracelab", "reason", str(rules), "--graph",
                          str(tmp_path / "g.graphml"), "--steps", "1", "--json"],
                         capture_output=True, text=True, check=True, timeout=600)
    final = json.loads(out.stdout)["interpretation"]
    assert sorted(a for a in final if a.startswith("knows")) == ["knows(a,b)", "knows(c,b)"]
    assert sorted(a for a in final if a.startswith("met")) == ["met(a,b)", "met(a,c)", "met(c,b)"]


def test_reason_cli_bad_closed_directive_is_one_line(tmp_path: Path) -> None:
    rules = tmp_path / "bad.rules"
    rules.write_text("q(a)\n%closed p q\n")
    out = subprocess.run([sys.executable, "-m", "tracelab", "reason", str(rules), "--steps", "1"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 1
    first = out.stderr.splitlines()[0]
    assert first.startswith("tracelab: error: ") and f"{rules}:2:11" in first and "Traceback" not in out.stderr


# ---- with quantifiers and annotation functions (docs/language.md, "With quantifiers and ...") -------

ZONE = """
zone(z)
in(z,a)
in(z,b)
in(z,c)
hostile(a)
quiet(Z) <-0 zone(Z), in(Z,A), [>= 60%] ~hostile(A)
watched(Z) <-0 zone(Z), in(Z,A), [forall available] ~hostile(A)
low(Z):min <-0 zone(Z), in(Z,A), hostile(A):[0,0.5]
"""


def test_quantified_clause_on_a_closed_predicate_reads_unset_atoms_as_false() -> None:
    (closed,) = run_all("%closed hostile\n" + ZONE, 1, lanes=False)
    (open_,) = run_all(ZONE, 1, lanes=False)
    # ~hostile(b), ~hostile(c) hold only when closed: 2 of 3 candidates
    assert closed["quiet(z)"] == (1.0, 1.0) and "quiet(z)" not in open_
    # available: only hostile(a) was set, and ~hostile(a) fails, closed or not
    assert "watched(z)" not in closed and "watched(z)" not in open_
    # the function gets the unset closed atoms as they read, [0,0]; open, no join holds
    assert closed["low(z)"] == (0.0, 0.0) and "low(z)" not in open_


def test_set_static_on_an_aggregated_rule_freezes_the_head_group() -> None:
    text = """%timesteps reset
zone(z) @0..4
in(z,a) @0..4
in(z,b) @0..4
hostile(a) @0..1
alarm(Z) <-0 zone(Z), in(Z,A), [>= 1] hostile(A) OPT
level(Z):max <-1 zone(Z), in(Z,A), hostile(A) {weights=0,0,1, OPT2}
"""
    frozen = run_all(text.replace("OPT2", "set_static").replace("OPT", "{set_static}"), 4, lanes=False)
    plain = run_all(text.replace(", OPT2", "").replace("OPT", ""), 4, lanes=False)
    assert [s.get("alarm(z)") for s in frozen] == [(1.0, 1.0)] * 4  # static through the resets
    assert [s.get("alarm(z)") for s in plain] == [(1.0, 1.0), (1.0, 1.0), None, None]
    assert [s.get("level(z)") for s in frozen] == [None, (1.0, 1.0), (1.0, 1.0), (1.0, 1.0)]
    assert [s.get("level(z)") for s in plain] == [None, (1.0, 1.0), (1.0, 1.0), None]


def test_edge_heads_graph_restricts_the_head_groups_of_an_aggregated_rule(graph) -> None:
    text = """%edge_heads graph
likes(a,b)
likes(a,c)
likes(c,b)
near(X,Y) <-0 person(X), person(Y), [>= 1] likes(X,Y)
reach(X,Y) <-0 person(X), person(Y), [>= 1] likes(X,Y) {infer_edges}
best(X,Y):max <-0 person(X), person(Y), likes(X,Y)
"""
    (s,) = run_all(text, 1, graph, lanes=False)
    assert true_atoms(s, "near") == ["near(a,b)", "near(c,b)"]  # (a,c) is no edge of the graph
    assert true_atoms(s, "reach") == ["reach(a,b)", "reach(a,c)", "reach(c,b)"]
    assert true_atoms(s, "best") == ["best(a,b)", "best(c,b)"]


# ---- head functions -------------------------------------------------------------------------------

HEAD_FUNCTIONS = """
%timesteps reset
prop(a) @0..3
prop(b) @0..3
conn(a,b) @0..3
conn(b,c) @1..3
processed(partner(X)) <-0 prop(X), conn(X,Y)
route(partner(X), Y) <-0 conn(X,Y)
seen(first_of(X, c)) <-1 processed(X)
"""


@pytest.fixture
def head_functions():
    from tracelab.engine import register_head_function, unregister_head_function
    register_head_function("partner", lambda x: {"a": "b", "b": "c", "c": "a"}[x])
    register_head_function("first_of", lambda x, y: min(x, y))
    yield
    unregister_head_function("partner")
    unregister_head_function("first_of")


def test_head_functions_compute_the_head_node_in_every_kernel(head_functions):
    """The head atom is the function's node for each grounding: reference, counting and lanes agree."""
    steps = run_all(HEAD_FUNCTIONS, 3)
    assert true_atoms(steps[0], "processed") == ["processed(b)"]  # partner(a) = b; b has no conn at t=0
    assert true_atoms(steps[1], "processed") == ["processed(b)", "processed(c)"]
    assert true_atoms(steps[1], "route") == ["route(b,b)", "route(c,c)"]
    assert true_atoms(steps[1], "seen") == ["seen(b)"]  # first_of(b, c) from processed(b) at t=0
    assert true_atoms(steps[2], "seen") == ["seen(b)", "seen(c)"]


@pytest.mark.parametrize("text, message", [
    ("processed(nope(X)) <-0 prop(X)\nprop(a)\n", "unknown head function 'nope'"),
    ("processed(partner(X,Y)) <-0 conn(X,Y)\nconn(a,b)\n", "head function 'partner' takes 1 argument, given 2"),
    ("p(partner(a))\n", "a fact must be ground: 'partner(a)' is a head function call"),
    ("p(partner(X)) <-0 q(X):[0,1]\n", "unsafe variable 'X'"),
    ("p(partner(X)):average <-0 q(X)\nq(a)\n", "cannot be combined with quantifiers or an annotation function"),
    ("p(X) <-0 q(partner(X))\n", "'partner(' is a head function call, which only a rule head's argument may be"),
])
def test_head_function_misuse_is_a_located_error(head_functions, text, message):
    with pytest.raises((ProgramCheckError, RuleSyntaxError)) as e:
        parse_program(text, "<test>")
    assert message in e.value.message and e.value.line == 1 and e.value.column > 1


def test_a_head_function_returning_an_unknown_node_is_a_located_error(head_functions):
    from tracelab.engine import register_head_function
    register_head_function("partner", lambda x: "nowhere")
    program = parse_program("prop(a)\nprocessed(partner(X)) <-0 prop(X)\n", "<test>")
    with pytest.raises(Exception, match=r"head function 'partner' .*returned 'nowhere'.*not a node") as e:
        Engine(program, kernel="counting").step()
    assert e.value.line == 2


COMPLEMENTARY = """
%timesteps reset
sick(a):[0.8,1] @0..2
healthy(b):[0.6,0.9] @0..2
healthy(c):[0.9,1] @0..2
contact(a,c) @0..2
sick(Y):[0.5,0.7] <-1 sick(X):[0.5,1], contact(X,Y)
~healthy(X):max <-0 sick(X):[0.000000002,1]
~healthy(X):max <-0 sick(X):[0,0.999999998]
~sick(X):max <-0 healthy(X):[0.000000002,1]
~sick(X):max <-0 healthy(X):[0,0.999999998]
"""


def test_complementary_predicates_by_rules():
    """docs/language.md "Complementary predicates": each side gets the other's complement (reference and
    counting kernel agree); sick(c) from the delayed rule at t=1 contradicts healthy(c): both reset, frozen."""
    steps = run_all(COMPLEMENTARY, 3, lanes=False)
    assert steps[0]["healthy(a)"] == pytest.approx((0.0, 0.2)) and steps[0]["sick(b)"] == pytest.approx((0.1, 0.4))
    assert steps[0]["sick(c)"] == pytest.approx((0.0, 0.1))
    for t in (1, 2):  # [0,1] (not listed); at t=2 the fact healthy(c) would set it again were it not frozen
        assert "sick(c)" not in steps[t] and "healthy(c)" not in steps[t]
    assert steps[2]["healthy(a)"] == pytest.approx((0.0, 0.2))
