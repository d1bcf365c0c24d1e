"""The rule trace's rows as PyReason writes them (issue 41): graph attributes, conflicting and
overlapping facts, the inconsistent predicate list's conflicts raised by a rule. Expected rows are
PyReason 3.8.0's committed traces (its examples/csv_outputs) or reasoned out from its code."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest

import tracelab.pyreason as pr

nx = pytest.importorskip("networkx")
pytest.importorskip("pandas")


@pytest.fixture(autouse=True)
def fresh() -> None:
    pr.reset()
    pr.reset_rules()
    pr.reset_settings()
    pr.api._program.ipl.clear()


def saved_node_rows(interpretation: pr.Interpretation, folder: Path) -> list[dict[str, str]]:
    pr.save_rule_trace(interpretation, str(folder))
    (nodes,) = folder.glob("rule_trace_nodes_*.csv")
    with open(nodes, encoding="utf-8", newline="") as f:
        return list(csv.DictReader(f))


def test_graph_attribute_rows_are_named_as_pyreason_names_them_non_ascii_kept(tmp_path: Path) -> None:
    # PyReason's user guide (6_pyreason_output.rst): a graph attribute's row reads `graph-attribute-fact`
    g = nx.DiGraph()
    g.add_node("Chișinău_International_Airport", **{"Chișinău_International_Airport": 1})
    g.add_node("Yali", Yali=1)
    pr.settings.save_graph_attributes_to_trace = True
    pr.load_graph(g)
    pr.add_rule(pr.Rule("airport(x) <- Yali(x)", "airport_rule"))
    rows = saved_node_rows(pr.reason(timesteps=0), tmp_path)
    graph_rows = [(r["Node"], r["Label"], r["Occurred Due To"]) for r in rows if r["Triggered By"] == "Fact"]
    assert graph_rows == [
        ("Chișinău_International_Airport", "Chișinău_International_Airport", "graph-attribute-fact"),
        ("Yali", "Yali", "graph-attribute-fact")]


def two_facts_each(first: str, second: str) -> pr.Interpretation:
    g = nx.DiGraph()
    g.add_nodes_from(["Bob", "a"])
    pr.load_graph(g)
    pr.add_rule(pr.Rule("rested(x) <- tired(x):[0,0.2]", "rest_rule"))
    pr.add_fact(pr.Fact(f"tired(Bob):{first}", "bob_tired_fact_1", 0, 0))
    pr.add_fact(pr.Fact(f"tired(Bob):{second}", "bob_tired_fact_2", 0, 0))
    return pr.reason(timesteps=0)


def test_conflicting_facts_are_two_rows_and_a_reset_as_pyreasons_committed_trace(tmp_path: Path) -> None:
    # PyReason's examples/csv_outputs/inconsistency_example_nodes_20260318-083700.csv, its tired(Bob) rows
    rows = saved_node_rows(two_facts_each("[0.8,1.0]", "[0.0,0.1]"), tmp_path)
    assert [list(r.values())[:10] for r in rows] == [
        ["0", "0", "Bob", "tired", "[0.0,1.0]", "[0.8,1.0]", "bob_tired_fact_1", "True", "Fact", ""],
        ["0", "0", "Bob", "tired", "[0.8,1.0]", "[0.0,1.0]", "bob_tired_fact_2", "False", "Fact",
         "Inconsistency occurred. Conflicting bounds for tired(Bob). Update from [0.800, 1.000] to [0.000, 0.100] "
         "is not allowed. Setting bounds to [0,1] and static=True for this timestep."]]


def test_overlapping_facts_are_a_row_each() -> None:
    interpretation = two_facts_each("[0.5,1.0]", "[0.2,0.9]")
    nodes, _ = pr.get_rule_trace(interpretation)
    assert nodes[["Old Bound", "New Bound", "Occurred Due To", "Consistent"]].values.tolist() == [
        ["[0.0,1.0]", "[0.5,1.0]", "bob_tired_fact_1", True], ["[0.5,1.0]", "[0.5,0.9]", "bob_tired_fact_2", True]]
    assert interpretation.get_dict()[0]["Bob"] == {"tired": (0.5, 0.9)}


def test_a_rule_that_contradicts_an_ipl_partner_resets_both_as_pyreason() -> None:
    # PyReason's examples/inconsistency_example.py, Carol: healthy(Carol) [0.9,1] makes sick(Carol) at most
    # 0.1, the spread rule then sets sick(Carol) [0.5,0.7]; PyReason resets both to [0,1] (its committed
    # trace: "Grounding sick(Carol) conflicts with grounding healthy(Carol)")
    g = nx.DiGraph()
    g.add_nodes_from(["Bob", "Carol"])
    g.add_edge("Bob", "Carol", contact=1)
    pr.load_graph(g)
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.add_rule(pr.Rule("sick(y):[0.5,0.7] <- sick(x):[0.5,1.0], contact(x,y)", "spread_rule"))
    pr.add_fact(pr.Fact("healthy(Carol):[0.9,1.0]", "carol_healthy_fact", 0, 0))
    pr.add_fact(pr.Fact("sick(Bob):[0.6,0.8]", "bob_sick_fact", 0, 0))
    interpretation = pr.reason(timesteps=0)
    carol = interpretation.get_dict()[0]["Carol"]
    assert carol.get("sick", (0.0, 1.0)) == (0.0, 1.0) and carol["healthy"] == (0.0, 1.0)
    assert not interpretation.query(pr.Query("healthy(Carol):[0.9,1.0]"))
    nodes, _ = pr.get_rule_trace(interpretation)
    (row,) = nodes[~nodes["Consistent"].astype(bool)].values.tolist()
    assert row[2:10] == ["Carol", "healthy", "[0.9,1.0]", "[0.0,1.0]", "spread_rule", False, "IPL",
                         "Inconsistency occurred. Grounding healthy(Carol) conflicts with grounding sick(Carol). "
                         "Setting bounds to [0,1] and static=True for this timestep."]


def test_a_rules_partner_row_comes_in_its_pass_as_pyreasons_committed_trace(tmp_path: Path) -> None:
    # PyReason's examples/csv_outputs/cybersecurity_rule_trace_nodes.csv: workstation_1's vulnerable row
    # by vulnerability_rule and its IPL row `patched`, in the same fixed-point operation, without clauses
    g = nx.DiGraph()
    g.add_node("workstation_1")
    pr.load_graph(g)
    pr.add_inconsistent_predicate("patched", "vulnerable")
    pr.add_rule(pr.Rule("vulnerable(x):[0.8,1.0] <- exposed(x)", "vulnerability_rule"))
    pr.add_fact(pr.Fact("exposed(workstation_1)", "exposed_fact", 0, 0))
    rows = saved_node_rows(pr.reason(timesteps=0), tmp_path)
    assert [list(r.values())[:11] for r in rows[1:]] == [
        ["0", "1", "workstation_1", "vulnerable", "[0.0,1.0]", "[0.8,1.0]", "vulnerability_rule", "True", "Rule", "",
         "['workstation_1']"],
        ["0", "1", "workstation_1", "patched", "[0.0,1.0]", "[0.0,0.19999999999999996]", "IPL: vulnerable", "True",
         "IPL", "", ""]]
