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
