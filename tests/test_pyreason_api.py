"""`import tracelab.pyreason as pr` beyond PyReason's own functional tests (tests/pyreason_functional):
recording into a tracelab run (`pr.settings.tracelab_run`, then `tracelab why`), convergence, rule
filtering by queries, the settings that change the graph, and the one-line errors of what is not
supported. Expected values are reasoned out per test from PyReason's semantics (docs/pyreason.md)."""
from __future__ import annotations

from pathlib import Path

import pytest

import tracelab.pyreason as pr
from tracelab.cli import main
from tracelab.engine import ProgramError
from tracelab.errors import UserError

nx = pytest.importorskip("networkx")
pytest.importorskip("pandas")

FRIENDS = str(Path(__file__).resolve().parent / "pyreason_functional" / "friends_graph.graphml")
HELLO_RULE = "popular(x) <-1 popular(y), Friends(x,y), owns(y,z), owns(x,z)"


@pytest.fixture(autouse=True)
def fresh() -> None:
    pr.reset()
    pr.reset_rules()
    pr.reset_settings()
    pr.settings.atom_trace = True  # the traces these tests read are PyReason's with atom_trace
    pr.api._program.ipl.clear()  # PyReason's reset() keeps the inconsistent predicate list; tests start without


def hello_world(end: int = 2) -> None:
    pr.load_graphml(FRIENDS)
    pr.add_rule(pr.Rule(HELLO_RULE, "popular_rule"))
    pr.add_fact(pr.Fact("popular(Mary)", "popular_fact", 0, end))


def popular(interpretation: pr.Interpretation) -> list[list[str]]:
    return [df["component"].tolist() for df in pr.filter_and_sort_nodes(interpretation, ["popular"])]


def test_tracelab_run_records_the_reasoning_for_tracelab_why(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    hello_world()
    pr.settings.tracelab_run = str(tmp_path / "run")
    pr.reason(timesteps=2)
    assert main(["why", str(tmp_path / "run"), 'popular("John")', "--episode", "0", "--at", "2"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("popular(John) = [1,1] at the end of t=2: set at t=2 pass 0 [0,1]->[1,1] by popular_rule")
    assert "popular(Justin):[1,1] = [1,1]: set at t=1" in out and "by fact:popular_fact" in out
    with pytest.raises(UserError, match="tracelab_run .* already holds a run"):
        pr.reason(timesteps=2)  # a run is never written over


def test_until_convergence_stops_when_nothing_is_pending() -> None:
    # Mary's fact holds at 0..2; popularity then moves Mary -> Justin -> John one step at a time, and
    # John is nobody's friend: at t=4 no fact starts later and no firing is pending (PyReason's
    # perfect convergence), so timesteps=-1 stops there
    hello_world()
    interpretation = pr.reason()
    assert interpretation.time == 4
    assert popular(interpretation) == [["Mary"], ["Mary", "Justin"], ["Mary", "John", "Justin"],
                                       ["John", "Justin"], ["John"]]


def test_convergence_threshold_stops_after_a_quiet_enough_step() -> None:
    hello_world()
    # t=0 sets the graph's facts too (more than 5 atoms); t=1 sets popular(Mary) and popular(Justin)
    assert pr.reason(timesteps=10, convergence_threshold=5).time == 1
    pr.reset(); pr.reset_rules()
    hello_world()
    assert pr.reason(timesteps=10, convergence_bound_threshold=0.5).time == 5  # t=5: only resets


def test_queries_keep_only_the_rules_they_need() -> None:
    hello_world()
    pr.add_rule(pr.Rule("lonely(x) <-1 popular(x)", "lonely_rule"))
    nodes, _ = pr.get_rule_trace(pr.reason(timesteps=2, queries=[pr.Query("popular(John)")]))
    assert set(nodes["Occurred Due To"]) == {"popular_fact", "popular_rule"}
    pr.reset(); pr.reset_rules()
    hello_world()
    pr.add_rule(pr.Rule("lonely(x) <-1 popular(x)", "lonely_rule"))
    nodes, _ = pr.get_rule_trace(pr.reason(timesteps=2))
    assert "lonely_rule" in set(nodes["Occurred Due To"])


def test_reverse_digraph_and_undirected_networkx_graphs() -> None:
    g = nx.DiGraph()
    g.add_edge("A", "B", link=1)
    rule, fact = pr.Rule("reached(y) <-1 reached(x), link(x,y)", "step"), pr.Fact("reached(B)", "start", 0, 1)
    pr.load_graph(g)
    pr.add_rule(rule)
    pr.add_fact(fact)
    assert not pr.reason(timesteps=1).query(pr.Query("reached(A)"))
    pr.reset(); pr.reset_rules()
    pr.settings.reverse_digraph = True  # PyReason reverses the edges when the graph is loaded
    pr.load_graph(g)
    pr.add_rule(rule)
    pr.add_fact(fact)
    assert pr.reason(timesteps=1).query(pr.Query("reached(A)"))
    pr.reset(); pr.reset_rules(); pr.reset_settings()
    pr.load_graph(nx.Graph([("A", "B", {"link": 1})]))  # undirected: both ways, as networkx's DiGraph(g)
    pr.add_rule(rule)
    pr.add_fact(fact)
    assert pr.reason(timesteps=1).query(pr.Query("reached(A)"))


def test_static_graph_facts_false_holds_the_graph_at_t0_only() -> None:
    g = nx.DiGraph()
    g.add_node("A", seed=1)
    pr.load_graph(g)
    pr.add_rule(pr.Rule("grown(x) <-0 seed(x)", "grow"))
    pr.add_fact(pr.Fact("clock(A)", "clock", 0, 2))  # a fact until t=2: no convergence before
    assert pr.reason(timesteps=2).get_dict()[2]["A"] == {"grown": (1.0, 1.0), "clock": (1.0, 1.0)}  # static seed
    pr.reset(); pr.reset_rules()
    pr.settings.static_graph_facts = False
    pr.load_graph(g)
    pr.add_rule(pr.Rule("grown(x) <-0 seed(x)", "grow"))
    pr.add_fact(pr.Fact("clock(A)", "clock", 0, 2))
    d = pr.reason(timesteps=2).get_dict()
    assert d[0]["A"] == {"grown": (1.0, 1.0), "clock": (1.0, 1.0)}
    assert d[2]["A"] == {"clock": (1.0, 1.0)}  # seed reset at t=1 and never set again


def test_what_is_not_supported_is_one_line_naming_it() -> None:
    with pytest.raises(pr.UnsupportedFeature) as e:
        pr.load_inconsistent_predicate_list("ipl.yaml")
    assert isinstance(e.value, UserError) and "\n" not in str(e.value)
    assert str(e.value).startswith("the inconsistent predicate list from a YAML file "
                                   "(load_inconsistent_predicate_list) is not supported by tracelab.pyreason")
    hello_world()
    with pytest.raises(ProgramError, match=r"1:39: error: a function call in the arguments of a body clause"):
        pr.Rule("Processed(X) <- property(identity_func(X))")  # located in the rule's text
    with pytest.raises(UserError, match="There are no rules"):
        pr.reset_rules()
        pr.reason(timesteps=1)
    pr.add_rule(pr.Rule(HELLO_RULE, "popular_rule"))  # the failed reason() kept the facts
    assert popular(pr.reason(timesteps=1)) == [["Mary"], ["Mary", "Justin"]]
    with pytest.raises(TypeError, match="persistent: value has to be a bool"):
        pr.settings.persistent = "yes"
    with pytest.raises(AttributeError, match="no setting 'persistant'"):
        pr.settings.persistant = True


def test_reason_again_continues_with_the_new_facts_and_the_pending_firings() -> None:
    # PyReason's test_reason_again (skipped there): Mary is popular at 0..1, then again at 2..4. Firings
    # scheduled at t=1 for t=2 (Justin from Mary, John from Justin) still land at t=2 here; PyReason drops
    # them (its documented bug: its test expects Mary alone at t=2)
    hello_world(end=1)
    first = pr.reason(timesteps=1)
    assert first.time == 1 and popular(first) == [["Mary"], ["Mary", "Justin"]]
    pr.add_fact(pr.Fact("popular(Mary)", "popular_fact2", 2, 4))
    again = pr.reason(timesteps=3, again=True, restart=False)
    assert again.time == 4
    assert popular(again) == [["Mary"], ["Mary", "Justin"], ["Mary", "John", "Justin"],
                              ["Mary", "John", "Justin"], ["Mary", "John", "Justin"]]
    nodes, _ = pr.get_rule_trace(again)
    assert nodes[(nodes["Time"] == 2) & (nodes["Node"] == "Mary")]["Occurred Due To"].tolist() == ["popular_fact2"]
    # restart=True (PyReason's default): the new facts' times count from the first new step (t=5)
    pr.add_fact(pr.Fact("popular(Mary)", "popular_fact3", 1, 1))
    assert popular(pr.reason(timesteps=2, again=True))[5:] == [["John", "Justin"], ["Mary", "John"]]


def test_annotation_functions_get_each_clauses_bounds_and_the_rules_weights() -> None:
    numba = pytest.importorskip("numba")

    @numba.njit
    def count_clauses(annotations, weights):  # noqa: ANN001, ANN202 - PyReason's signature
        return len(annotations[0]) * 0.1, 0.5 + len(annotations[1]) * 0.1 + weights[1] * 0.01

    g = nx.DiGraph()
    g.add_edge("a", "b", link=1)
    g.add_edge("a", "c", link=1)
    g.add_edge("b", "c", link=1)
    g.add_node("b", score=0.5)
    g.add_node("c", score=0.9)
    pr.load_graph(g)
    pr.add_annotation_function(count_clauses)
    pr.add_rule(pr.Rule("h(x):count_clauses <-0 link(x,y), score(y):[0.5,1]", "r", weights=[1, 3]))
    interpretation = pr.reason(timesteps=0)
    # a: two link atoms and two score atoms counted, the second clause's weight 3
    assert interpretation.query(pr.Query("h(a):[0,1]"), return_bool=False) == (0.2, 0.73)
    assert interpretation.query(pr.Query("h(b):[0,1]"), return_bool=False) == (0.1, 0.63)


def test_classifier_outputs_become_facts_with_pyreasons_bounds() -> None:
    torch = pytest.importorskip("torch")
    options = pr.ModelInterfaceOptions(threshold=0.5, set_lower_bound=True, set_upper_bound=False, snap_value=0.95)
    classifier = pr.LogicIntegratedClassifier(torch.nn.Identity(), ["cat", "dog", "rabbit"], identifier="img1",
                                              interface_options=options)
    _, probabilities, facts = classifier(torch.tensor([[2.0, 0.0, 0.0]]), 1, 3)
    assert probabilities[0, 0].item() > 0.5 > probabilities[0, 1].item()  # softmax: cat 0.79, dog and rabbit 0.11
    assert [(f.name, f.literal.pred, f.literal.args, f.literal.lower, f.literal.upper, f.start_time, f.end_time)
            for f in facts] == [("img1-cat-fact", "cat", ("img1",), 0.95, 1.0, 1, 3),
                                ("img1-dog-fact", "dog", ("img1",), 0.0, 1.0, 1, 3),
                                ("img1-rabbit-fact", "rabbit", ("img1",), 0.0, 1.0, 1, 3)]


def test_rules_and_facts_from_pyreasons_files() -> None:
    data = Path(__file__).resolve().parent / "data" / "pyreason"
    pr.load_graphml(data / "group_chat.graphml")
    pr.add_rule_from_json(str(data / "viewed_rules.json"))  # its custom thresholds: viewed by all
    pr.add_fact_from_csv(str(data / "viewed_facts.csv"))
    assert [r.get_rule_name() for r in pr.get_rules()] == ["viewed_by_all_rule"]
    frames = pr.filter_and_sort_nodes(pr.reason(timesteps=3), ["ViewedByAll"])
    # PyReason's custom-thresholds tutorial, "Expected output": TextMessage from t=2 on
    assert [df["component"].tolist() for df in frames] == [[], [], ["TextMessage"], ["TextMessage"]]
    pr.reset(); pr.reset_rules()
    pr.load_graphml(data / "friends_graph.graphml")
    pr.add_rules_from_file(str(data / "hello_rules.txt"))  # the comment line skipped, named rule_0
    pr.add_fact_from_csv(str(data / "hello_facts.csv"))
    nodes, _ = pr.get_rule_trace(pr.reason(timesteps=2))
    assert nodes["Occurred Due To"].tolist() == ["popular_fact", "popular_fact", "rule_0", "popular_fact",
                                                 "rule_0", "rule_0"]


# ---- head functions (docs/pyreason.md "Head functions") ---------------------------------------------

def successor(args):
    """A PyReason head function in plain Python: the node after the first argument's node."""
    return [{"A": "B", "B": "C", "C": "A"}[args[0][0]]]


def both(args):
    return [args[0][0], "C"]


def chain() -> None:
    g = nx.DiGraph()
    g.add_nodes_from(["A", "B", "C"], property=1)
    g.add_edge("A", "B", connected=1)
    g.add_edge("B", "C", connected=1)
    pr.load_graph(g)


def test_a_head_function_is_called_per_grounding() -> None:
    """Processed(successor(X)): X grounds to A and B (the sources of an edge), so B and C are processed,
    not A; Next(X, successor(X)) stays on the graph's edges (A->B, B->C) as PyReason's edge heads do."""
    chain()
    pr.add_head_function(successor)
    pr.add_rule(pr.Rule("Processed(successor(X)) <- property(X), connected(X, Y)", "node_rule"))
    pr.add_rule(pr.Rule("Next(X, successor(X)) <- property(X), connected(X, Y)", "edge_rule"))
    interp = pr.reason(timesteps=0)
    assert [df["component"].tolist() for df in pr.filter_and_sort_nodes(interp, ["Processed"])] == [["B", "C"]]
    assert interp.query(pr.Query("Next(A, B)")) and interp.query(pr.Query("Next(B, C)"))
    assert not interp.query(pr.Query("Processed(A)"))


def test_why_not_names_a_head_function_rules_head_from_the_run(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    """The run does not store the Python function: why-not reads the head atom off the change a grounding
    with the same head values made (successor(A) is B, not A), and says so in one line when none made one
    (X=B's head, Processed(C), was already set by a fact: the firing changed nothing)."""
    chain()
    pr.add_head_function(successor)
    pr.add_rule(pr.Rule("Processed(successor(X)) <- property(X), connected(X, Y)", "node_rule"))
    pr.add_fact(pr.Fact("Processed(C)", "c_fact", 0, 0))
    pr.settings.tracelab_run = str(tmp_path / "run")
    pr.reason(timesteps=0)
    run = ["why-not", str(tmp_path / "run"), "--episode", "0", "--rule", "node_rule", "--at", "0"]
    assert main([*run, "--grounding", "X=A"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == ("every body clause holds: the rule was active; "
                                                        "its head processed(B) = [1,1] at the end of t=0")
    assert main([*run, "--grounding", "X=B"]) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    assert last.startswith("every body clause holds: the rule was active; its head calls the head function "
                           "pyreason_0_successor(X), which the run does not store") and "unknown" in last


def test_head_function_misuse_is_one_located_line() -> None:
    chain()
    pr.add_rule(pr.Rule("Processed(missing_fn(X)) <- property(X)", "r"))
    with pytest.raises(ProgramError, match=r"unknown head function 'missing_fn'") as e:
        pr.reason(timesteps=0)
    assert e.value.file == "<Rule 'r'>" and "\n" not in e.value.message
    pr.reset_rules()
    pr.add_head_function(both)
    pr.add_rule(pr.Rule("Processed(both(X)) <- property(X)", "r2"))
    with pytest.raises(ProgramError, match=r"both returned \['A', 'C'\] .* exactly one node name"):
        pr.reason(timesteps=0)


# ---- the inconsistent predicate list (docs/pyreason.md "The inconsistent predicate list") -----------

def contact_graph() -> None:
    g = nx.DiGraph()
    g.add_nodes_from(["Alice", "Bob", "Carol"])
    g.add_edge("Alice", "Bob", contact=1)
    pr.load_graph(g)


def test_inconsistent_predicates_are_kept_complementary() -> None:
    """sick(Alice) [0.8,1] makes healthy(Alice) [0,0.2]; the rule's sick(Bob) [0.5,0.7] makes healthy(Bob)
    [0.3,0.5]; a healthy fact on Carol makes sick(Carol) its complement (the pair works both ways)."""
    contact_graph()
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.add_rule(pr.Rule("sick(y):[0.5,0.7] <- sick(x):[0.5,1.0], contact(x,y)", "spread"))
    pr.add_fact(pr.Fact("sick(Alice):[0.8,1.0]", "alice_sick", 0, 1))
    pr.add_fact(pr.Fact("healthy(Carol):[0.6,0.9]", "carol_healthy", 0, 1))
    d = pr.reason(timesteps=1).get_dict()
    for t in (0, 1):
        assert d[t]["Alice"]["healthy"] == pytest.approx((0.0, 0.2))
        assert d[t]["Bob"]["sick"] == (0.5, 0.7) and d[t]["Bob"]["healthy"] == pytest.approx((0.3, 0.5))
        assert d[t]["Carol"]["sick"] == pytest.approx((0.1, 0.4))


def test_a_conflict_with_the_partner_resets_and_freezes_both_as_pyreason_reports_it() -> None:
    """healthy(Bob) [0.9,1] from t=0 and the rule's sick(Bob) [0.5,0.7] at t=1 conflict: both atoms are [0,1]
    and frozen from then on (t=2 too), with PyReason's IPL rows and message."""
    contact_graph()
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.add_rule(pr.Rule("sick(y):[0.5,0.7] <-1 sick(x):[0.5,1.0], contact(x,y)", "spread"))
    pr.add_fact(pr.Fact("sick(Alice):[0.8,1.0]", "alice_sick", 0, 2))
    pr.add_fact(pr.Fact("healthy(Bob):[0.9,1.0]", "bob_healthy", 0, 2))
    interp = pr.reason(timesteps=2)
    d = interp.get_dict()
    assert d[0]["Bob"] == {"healthy": (0.9, 1.0), "sick": pytest.approx((0.0, 0.1))}
    assert d[1]["Bob"] == {"sick": (0.0, 1.0), "healthy": (0.0, 1.0)}
    assert d[2]["Bob"].get("sick", (0.0, 1.0)) == (0.0, 1.0)  # frozen: the rule's firing at t=2 is ignored
    assert not interp.query(pr.Query("sick(Bob):[0.5,0.7]"))
    nodes, _ = pr.get_rule_trace(interp)
    bad = nodes[~nodes["Consistent"].astype(bool)]
    assert set(bad["Label"]) == {"sick", "healthy"} and set(bad["Time"]) == {1}
    assert set(bad["Triggered By"]) <= {"IPL", "Rule"} and "IPL" in set(bad["Triggered By"])
    # PyReason's resolve_inconsistency names the conflicting update's grounding (the rule's sick) first
    assert set(bad["Inconsistency Message"]) == {
        "Inconsistency occurred. Grounding sick(Bob) conflicts with grounding healthy(Bob). Setting bounds to [0,1] "
        "and static=True for this timestep."}
    assert bad[["Label", "Occurred Due To", "Triggered By"]].values.tolist() == [
        ["sick", "spread", "Rule"], ["healthy", "spread", "IPL"]]


def test_an_edge_pair_is_complementary_on_inferred_edges_too() -> None:
    contact_graph()
    pr.add_inconsistent_predicate("trusts", "distrusts")
    pr.add_rule(pr.Rule("trusts(x,y):[0.7,1] <- met(x), met(y)", "trust", infer_edges=True))
    pr.add_fact(pr.Fact("met(Alice)", "m1", 0, 0))
    pr.add_fact(pr.Fact("met(Carol)", "m2", 0, 0))
    d = pr.reason(timesteps=0).get_dict()
    assert d[0][("Alice", "Carol")]["distrusts"] == pytest.approx((0.0, 0.3))  # Alice->Carol is not a graph edge


# ---- one predicate on nodes and on edges (docs/pyreason.md "What maps to what") ----------------------

def test_one_predicate_on_nodes_and_on_edges_stays_two_labels() -> None:
    """PyReason keeps node and edge labels apart: `risk` on nodes and on edges (graph and rules) are two
    labels, each queried, filtered and traced as `risk`."""
    g = nx.DiGraph()
    g.add_node("A", risk=1)
    g.add_node("B")
    g.add_edge("A", "B", risk=1)
    pr.load_graph(g)
    pr.add_rule(pr.Rule("risk(y) <-1 risk(x), risk(x,y)", "node_risk"))
    pr.add_rule(pr.Rule("risk(y,x) <-0 risk(x,y)", "back", infer_edges=True))
    interp = pr.reason(timesteps=1)
    assert interp.query(pr.Query("risk(B)")) and interp.query(pr.Query("risk(B,A)"))
    assert not interp.query(pr.Query("risk(A,A)"))
    assert [df["component"].tolist() for df in pr.filter_and_sort_nodes(interp, ["risk"])][-1] == ["B"]
    assert [df["component"].tolist() for df in pr.filter_and_sort_edges(interp, ["risk"])][0] == [("B", "A")]


def test_the_inconsistent_predicate_list_outlives_reset_as_in_pyreason() -> None:
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.reset()
    pr.reset_rules()
    contact_graph()
    pr.add_rule(pr.Rule("sick(y) <- sick(x), contact(x,y)", "spread"))
    pr.add_fact(pr.Fact("sick(Alice)", "alice_sick", 0, 0))
    assert pr.reason(timesteps=0).get_dict()[0]["Bob"]["healthy"] == (0.0, 0.0)


def test_a_closed_clause_with_its_own_variable_ranges_over_the_nodes() -> None:
    # PyReason's examples/closed_world_pred_ex.py: `~hackerControl(X)` with X in no other clause holds for
    # some node whose hackerControl is unset (closed: [0,0]), so inconsistent(cb_2) at t = 1
    g = nx.DiGraph()
    g.add_nodes_from(["cb_1", "cb_2", "l1", "l2"])
    g.add_edge("cb_1", "cb_2", stepFrom=1)
    g.add_edge("cb_1", "l1", hasLabel=1)
    g.add_edge("cb_2", "l2", hasLabel=1)
    pr.load_graph(g)
    pr.add_closed_world_predicate("hackerControl")
    pr.add_fact(pr.Fact("stepFrom(cb_1, cb_2)", "step_from_fact", 0, 1))
    pr.add_fact(pr.Fact("hackerControl(cb_1)", "hacker_control_initial_fact", 0, 0))
    pr.add_rule(pr.Rule("future(Y) <-1 stepFrom(X,Y), hackerControl(X)"))
    pr.add_rule(pr.Rule("inconsistent(Y) <- future(Y), ~hackerControl(Y), ~hackerControl(X)", "inconsistent_rule"))
    interpretation = pr.reason(timesteps=2)
    assert [df["component"].tolist() for df in pr.filter_and_sort_nodes(interpretation, ["inconsistent"])][:2] == \
        [[], ["cb_2"]]
    nodes, _ = pr.get_rule_trace(interpretation)
    row = nodes[nodes["Label"] == "inconsistent"].iloc[0]
    assert row["Clause-1"] == ["cb_2"] and row["Clause-2"] == ["cb_2"] and len(row["Clause-3"]) == 1
    assert "Clause-4" not in nodes.columns  # the translation's node clause is not PyReason's
    assert "pyreason_node_domain" not in set(nodes["Label"])


def test_reason_again_applies_rules_added_since_and_names_each_new_fact() -> None:
    # PyReason's user guide, section 8: "To specify additional facts or rules, you can add them as you
    # normally would"; each fact's row names that fact, however many again=True calls came before
    hello_world(end=1)
    pr.reason(timesteps=1)
    pr.add_fact(pr.Fact("rich(Justin)", "fact_justin", 0, 0))
    pr.add_fact(pr.Fact("rich(John)", "fact_john", 0, 0))
    pr.add_rule(pr.Rule("happy(x) <- rich(x)", "happy_rule"))
    pr.reason(timesteps=1, again=True)
    pr.add_fact(pr.Fact("rich(Mary)", "fact_mary", 0, 0))
    pr.add_fact(pr.Fact("rich(Cat)", "fact_cat", 0, 0))
    nodes, _ = pr.get_rule_trace(pr.reason(timesteps=1, again=True))
    rows = nodes[nodes["Label"].isin(["rich", "happy"])][["Time", "Node", "Label", "Occurred Due To"]]
    assert rows.values.tolist() == [
        [2, "Justin", "rich", "fact_justin"], [2, "John", "rich", "fact_john"],
        [2, "John", "happy", "happy_rule"], [2, "Justin", "happy", "happy_rule"],
        [3, "Mary", "rich", "fact_mary"], [3, "Cat", "rich", "fact_cat"],
        [3, "Mary", "happy", "happy_rule"], [3, "Cat", "happy", "happy_rule"]]
    assert nodes["Time"].tolist()[:3] == [0, 1, 1]  # the first call's rows are kept


def test_a_comparison_clause_is_located_and_says_what_pyreason_does_with_it() -> None:
    # PyReason's creating-rules tutorial: `c_id(x) != c_id(y)`; PyReason 3.x parses it and skips it when
    # grounding (interpretation.py: "This is a comparison clause: pass")
    with pytest.raises(ProgramError) as e:
        pr.Rule("car_friend(x,y) <- owns_car(x,z), owns_car(y,z) , c_id(x) != c_id(y) ", "car_friend_rule")
    assert e.value.column == 59 and "PyReason added them in 1.8.11" in e.value.message
    assert "since 3.0.0 its grounding skips them" in e.value.message and "without this clause" in e.value.message
