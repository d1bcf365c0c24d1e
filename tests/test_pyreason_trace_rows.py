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
    pr.settings.atom_trace = True  # the rows these tests hold are PyReason's with atom_trace (its committed traces)
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


def csv_rows(interpretation: pr.Interpretation, folder: Path, which: str = "nodes") -> list[str]:
    """The saved trace's lines after the header, as PyReason's committed CSVs hold them."""
    for old in folder.glob("rule_trace_*.csv"):
        old.unlink()
    pr.save_rule_trace(interpretation, str(folder))
    (path,) = folder.glob(f"rule_trace_{which}_*.csv")
    return path.read_text(encoding="utf-8").splitlines()[1:]


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


def test_a_rule_that_contradicts_an_ipl_partner_resets_both_as_pyreason(tmp_path: Path) -> None:
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
    # the committed trace's rows for Carol: the IPL row of the fact's pass, then the rule's conflict with its
    # clauses and the partner's reset naming the rule; Bob's IPL row in the fact's pass too
    message = ("Inconsistency occurred. Grounding sick(Carol) conflicts with grounding healthy(Carol). "
               "Setting bounds to [0,1] and static=True for this timestep.")
    assert csv_rows(interpretation, tmp_path) == [
        '0,0,Carol,healthy,"[0.0,1.0]","[0.9,1.0]",carol_healthy_fact,True,Fact,,,',
        '0,0,Carol,sick,"[0.0,1.0]","[0.0,0.09999999999999998]",IPL: healthy,True,IPL,,,',
        '0,0,Bob,sick,"[0.0,1.0]","[0.6,0.8]",bob_sick_fact,True,Fact,,,',
        '0,0,Bob,healthy,"[0.0,1.0]","[0.19999999999999996,0.4]",IPL: sick,True,IPL,,,',
        f'0,1,Carol,sick,"[0.0,0.09999999999999998]","[0.0,1.0]",spread_rule,False,Rule,"{message}",[\'Bob\'],'
        '"[(\'Bob\', \'Carol\')]"',
        f'0,1,Carol,healthy,"[0.9,1.0]","[0.0,1.0]",spread_rule,False,IPL,"{message}",,']


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


def inconsistency_example() -> pr.Interpretation:
    """PyReason's examples/inconsistency_example.py (its program; printing left out)."""
    g = nx.DiGraph()
    g.add_nodes_from(["Alice", "Bob", "Carol", "Dave"])
    for a, b in (("Alice", "Bob"), ("Bob", "Carol"), ("Bob", "Dave")):
        g.add_edge(a, b, contact=1)
    pr.settings.atom_trace = True
    pr.load_graph(g)
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.add_inconsistent_predicate("close_contact", "no_contact")
    for rule, name in (("sick(y):[0.5,0.7] <- sick(x):[0.5,1.0], contact(x,y)", "spread_rule"),
                       ("no_contact(x,y):[0.8,1.0] <- sick(x):[0.5,1.0], sick(y):[0.5,1.0], contact(x,y)",
                        "quarantine_rule"),
                       ("trust(x,y):[0.0,0.2] <- sick(x):[0.5,1.0], contact(x,y)", "distrust_rule"),
                       ("risk(x,y):[0.6,0.8] <- sick(x):[0.5,1.0], contact(x,y)", "risk_rule")):
        pr.add_rule(pr.Rule(rule, name))
    for fact, name in (("sick(Alice):[0.8,1.0]", "alice_sick_fact"), ("healthy(Alice):[0.9,1.0]", "alice_healthy_fact"),
                       ("sick(Bob):[0.6,0.8]", "bob_sick_fact"), ("healthy(Carol):[0.9,1.0]", "carol_healthy_fact"),
                       ("tired(Bob):[0.8,1.0]", "bob_tired_fact_1"), ("tired(Bob):[0.0,0.1]", "bob_tired_fact_2"),
                       ("close_contact(Alice,Bob):[0.8,1.0]", "alice_bob_close_fact"),
                       ("trust(Bob,Carol):[0.9,1.0]", "bob_carol_trust_high")):
        pr.add_fact(pr.Fact(fact, name, 0, 0))
    return pr.reason(timesteps=2)


# PyReason's examples/csv_outputs/inconsistency_example_{nodes,edges}_20260318-083700.csv, after the header
INCONSISTENCY_EXAMPLE_NODES = [
    '0,0,Alice,sick,"[0.0,1.0]","[0.8,1.0]",alice_sick_fact,True,Fact,,,',
    '0,0,Alice,healthy,"[0.0,1.0]","[0.0,0.19999999999999996]",IPL: sick,True,IPL,,,',
    '0,0,Alice,healthy,"[0.0,0.19999999999999996]","[0.0,1.0]",alice_healthy_fact,False,Fact,"Inconsistency occurred. Grounding healthy(Alice) conflicts with grounding sick(Alice). Setting bounds to [0,1] and static=True for this timestep.",,',  # noqa: E501 (PyReason's line as it is)
    '0,0,Alice,sick,"[0.8,1.0]","[0.0,1.0]",alice_healthy_fact,False,IPL,"Inconsistency occurred. Grounding healthy(Alice) conflicts with grounding sick(Alice). Setting bounds to [0,1] and static=True for this timestep.",,',  # noqa: E501 (PyReason's line as it is)
    '0,0,Bob,sick,"[0.0,1.0]","[0.6,0.8]",bob_sick_fact,True,Fact,,,',
    '0,0,Bob,healthy,"[0.0,1.0]","[0.19999999999999996,0.4]",IPL: sick,True,IPL,,,',
    '0,0,Carol,healthy,"[0.0,1.0]","[0.9,1.0]",carol_healthy_fact,True,Fact,,,',
    '0,0,Carol,sick,"[0.0,1.0]","[0.0,0.09999999999999998]",IPL: healthy,True,IPL,,,',
    '0,0,Bob,tired,"[0.0,1.0]","[0.8,1.0]",bob_tired_fact_1,True,Fact,,,',
    '0,0,Bob,tired,"[0.8,1.0]","[0.0,1.0]",bob_tired_fact_2,False,Fact,"Inconsistency occurred. Conflicting bounds for tired(Bob). Update from [0.800, 1.000] to [0.000, 0.100] is not allowed. Setting bounds to [0,1] and static=True for this timestep.",,',  # noqa: E501 (PyReason's line as it is)
    '0,1,Carol,sick,"[0.0,0.09999999999999998]","[0.0,1.0]",spread_rule,False,Rule,"Inconsistency occurred. Grounding sick(Carol) conflicts with grounding healthy(Carol). Setting bounds to [0,1] and static=True for this timestep.",[\'Bob\'],"[(\'Bob\', \'Carol\')]"',  # noqa: E501 (PyReason's line as it is)
    '0,1,Carol,healthy,"[0.9,1.0]","[0.0,1.0]",spread_rule,False,IPL,"Inconsistency occurred. Grounding sick(Carol) conflicts with grounding healthy(Carol). Setting bounds to [0,1] and static=True for this timestep.",,',  # noqa: E501 (PyReason's line as it is)
    '0,1,Dave,sick,"[0.0,1.0]","[0.5,0.7]",spread_rule,True,Rule,,[\'Bob\'],"[(\'Bob\', \'Dave\')]"',
    '0,1,Dave,healthy,"[0.0,1.0]","[0.30000000000000004,0.5]",IPL: sick,True,IPL,,,',
]
INCONSISTENCY_EXAMPLE_EDGES = [
    '0,0,"(\'Alice\', \'Bob\')",close_contact,"[0.0,1.0]","[0.8,1.0]",alice_bob_close_fact,True,Fact,,,,',
    '0,0,"(\'Alice\', \'Bob\')",no_contact,"[0.0,1.0]","[0.0,0.19999999999999996]",IPL: close_contact,True,IPL,,,,',
    '0,0,"(\'Bob\', \'Carol\')",trust,"[0.0,1.0]","[0.9,1.0]",bob_carol_trust_high,True,Fact,,,,',
    '0,1,"(\'Bob\', \'Carol\')",trust,"[0.9,1.0]","[0.0,1.0]",distrust_rule,False,Rule,"Inconsistency occurred. Conflicting bounds for trust(Bob,Carol). Update from [0.900, 1.000] to [0.000, 0.200] is not allowed. Setting bounds to [0,1] and static=True for this timestep.",[\'Bob\'],"[(\'Bob\', \'Carol\')]",',  # noqa: E501 (PyReason's line as it is)
    '0,1,"(\'Bob\', \'Dave\')",trust,"[0.0,1.0]","[0.0,0.2]",distrust_rule,True,Rule,,[\'Bob\'],"[(\'Bob\', \'Dave\')]",',  # noqa: E501 (PyReason's line as it is)
    '0,1,"(\'Bob\', \'Carol\')",risk,"[0.0,1.0]","[0.6,0.8]",risk_rule,True,Rule,,[\'Bob\'],"[(\'Bob\', \'Carol\')]",',
    '0,1,"(\'Bob\', \'Dave\')",risk,"[0.0,1.0]","[0.6,0.8]",risk_rule,True,Rule,,[\'Bob\'],"[(\'Bob\', \'Dave\')]",',
    '0,2,"(\'Bob\', \'Dave\')",no_contact,"[0.0,1.0]","[0.8,1.0]",quarantine_rule,True,Rule,,[\'Bob\'],[\'Dave\'],"[(\'Bob\', \'Dave\')]"',  # noqa: E501 (PyReason's line as it is)
    '0,2,"(\'Bob\', \'Dave\')",close_contact,"[0.0,1.0]","[0.0,0.19999999999999996]",IPL: no_contact,True,IPL,,,,',
]


def test_the_inconsistency_example_trace_is_pyreasons_committed_one(tmp_path: Path) -> None:
    interpretation = inconsistency_example()
    assert csv_rows(interpretation, tmp_path) == INCONSISTENCY_EXAMPLE_NODES
    assert csv_rows(interpretation, tmp_path, "edges") == INCONSISTENCY_EXAMPLE_EDGES


def cybersecurity_example() -> pr.Interpretation:
    """PyReason's examples/cybersecurity_inconsistency_ex.py (its program; printing left out)."""
    g = nx.DiGraph()
    g.add_nodes_from(["web_server", "workstation_1", "dev_server", "sudo_1_9_5p1", "linux_kernel_5_1",
                      "openssl_3_0_1", "cve_2021_3156", "cve_2022_0185", "cve_2022_26923"])
    for a, b in (("web_server", "sudo_1_9_5p1"), ("workstation_1", "linux_kernel_5_1"),
                 ("dev_server", "openssl_3_0_1")):
        g.add_edge(a, b, runs=1)
    for a, b in (("sudo_1_9_5p1", "cve_2021_3156"), ("linux_kernel_5_1", "cve_2022_0185"),
                 ("openssl_3_0_1", "cve_2022_26923")):
        g.add_edge(a, b, has_cve=1)
    pr.settings.atom_trace = True
    pr.load_graph(g)
    pr.add_inconsistent_predicate("vulnerable", "patched")
    for rule, name in (("at_risk(X) <- runs(X,Y), has_cve(Y,Z)", "exposure_rule"),
                       ("vulnerable(X):[0.8,1.0] <- at_risk(X)", "vulnerability_rule"),
                       ("compromised(X):[0.8,1.0] <- vulnerable(X):[0.5,1.0]", "compromise_rule"),
                       ("patch_confidence(X):[0.0,0.2] <- compromised(X):[0.5,1.0]", "unpatched_rule")):
        pr.add_rule(pr.Rule(rule, name))
    for fact, name in (("severity(cve_2021_3156):[0.78,0.78]", "sudo_cve_severity"),
                       ("severity(cve_2022_0185):[0.84,0.84]", "kernel_cve_severity"),
                       ("severity(cve_2022_26923):[0.75,0.75]", "openssl_cve_severity"),
                       ("severity(cve_2021_3156):[0.8,1.0]", "severity_source_A"),
                       ("severity(cve_2021_3156):[0.0,0.1]", "severity_source_B"),
                       ("patched(web_server):[0.9,1.0]", "patch_db_fact"),
                       ("vulnerable(web_server):[0.9,1.0]", "vuln_scanner_fact"),
                       ("patch_confidence(dev_server):[0.9,1.0]", "dev_patch_db_fact")):
        pr.add_fact(pr.Fact(fact, name, 0, 3))
    return pr.reason(timesteps=3)


def test_facts_on_frozen_atoms_are_rows_as_pyreasons_committed_cybersecurity_trace(tmp_path: Path) -> None:
    # PyReason writes a row for each fact on an atom a conflict froze (the fact's bound as old and new),
    # and its IPL partner's row ([0,1] -> [0,1]), in the conflict's step and every later one
    committed = (Path(__file__).parent / "pyreason_traces" / "cybersecurity_rule_trace_nodes.csv")
    expected = list(csv.reader(committed.read_text(encoding="utf-8").splitlines()[1:]))
    got = list(csv.reader(csv_rows(cybersecurity_example(), tmp_path)))
    # Clause-2 of exposure_rule's rows differs as documented (docs/pyreason.md, "The rule trace's rows":
    # the grounding's atoms; PyReason lists every has_cve edge)
    assert [r[:11] for r in got] == [r[:11] for r in expected]
    assert [r[11] for r in got if r[6] != "exposure_rule"] == [r[11] for r in expected if r[6] != "exposure_rule"]


def test_a_set_static_rule_freezes_its_ipl_partner_too_as_pyreason(tmp_path: Path) -> None:
    # PyReason's _update_node sets the partner's static flag with the update's (`set_static(static)`):
    # a set_static rule on sick(a) freezes healthy(a) at the complement, kept through the non-persistent
    # resets, and a later fact on it is a row on a frozen atom (its own bound), not a conflict
    g = nx.DiGraph()
    g.add_node("a")
    pr.load_graph(g)
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.add_fact(pr.Fact("p(a)", "f_p", 0, 0))
    pr.add_fact(pr.Fact("healthy(a):[0.9,1]", "f_h", 2, 2))
    pr.add_rule(pr.Rule("sick(x):[0.8,1] <- p(x)", "r", set_static=True))
    interpretation = pr.reason(timesteps=3)
    assert interpretation.query(pr.Query("healthy(a) : [0, 0.2]"), return_bool=False) == (0.0, 1 - 0.8)
    assert interpretation.query(pr.Query("sick(a) : [0.8, 1]"))
    rows = [(r["Time"], r["Label"], r["Old Bound"], r["New Bound"], r["Occurred Due To"], r["Consistent"],
             r["Triggered By"]) for r in saved_node_rows(interpretation, tmp_path)]
    partner = f"[0.0,{1 - 0.8!r}]"
    assert rows == [("0", "p", "[0.0,1.0]", "[1.0,1.0]", "f_p", "True", "Fact"),
                    ("0", "sick", "[0.0,1.0]", "[0.8,1.0]", "r", "True", "Rule"),
                    ("0", "healthy", "[0.0,1.0]", partner, "IPL: sick", "True", "IPL"),
                    ("2", "healthy", "[0.9,1.0]", "[0.9,1.0]", "f_h", "True", "Fact"),
                    ("2", "sick", "[0.8,1.0]", "[0.8,1.0]", "f_h", "True", "IPL")]


def basic_tutorial() -> pr.Interpretation:
    """PyReason's examples/basic_tutorial_ex.py: its graph, rule and fact, default settings."""
    g = nx.DiGraph()
    g.add_nodes_from(["John", "Mary", "Justin", "Dog", "Cat"])
    for a, b in [("Justin", "Mary"), ("John", "Mary"), ("John", "Justin")]:
        g.add_edge(a, b, Friends=1)
    for a, b in [("Mary", "Cat"), ("Justin", "Cat"), ("Justin", "Dog"), ("John", "Dog")]:
        g.add_edge(a, b, owns=1)
    pr.load_graph(g)
    pr.add_rule(pr.Rule("popular(x) <-1 popular(y), Friends(x,y), owns(y,z), owns(x,z)", "popular_rule"))
    pr.add_fact(pr.Fact("popular(Mary)", "popular_fact", 0, 2))
    return pr.reason(timesteps=2)


def test_without_atom_trace_the_trace_has_pyreasons_short_layout(tmp_path: Path) -> None:
    # PyReason's default atom_trace=False: its Output writes '-' for the old bound and the cause, no
    # message and no clause columns (pyreason/scripts/utils/output.py). The first 7 columns are its
    # committed examples/csv_outputs/basic_rule_trace_nodes_20241125-114246.csv, row for row.
    pr.settings.atom_trace = False
    interpretation = basic_tutorial()
    assert csv_rows(interpretation, tmp_path) == [
        '0,0,Mary,popular,-,"[1.0,1.0]",-,True,Fact,',
        '1,1,Mary,popular,-,"[1.0,1.0]",-,True,Fact,',
        '1,1,Justin,popular,-,"[1.0,1.0]",-,True,Rule,',
        '2,2,Mary,popular,-,"[1.0,1.0]",-,True,Fact,',
        '2,2,John,popular,-,"[1.0,1.0]",-,True,Rule,',
        '2,2,Justin,popular,-,"[1.0,1.0]",-,True,Rule,']
    nodes, edges = pr.get_rule_trace(interpretation)
    assert list(nodes.columns) == ["Time", "Fixed-Point-Operation", "Node", "Label", "Old Bound", "New Bound",
                                   "Occurred Due To", "Consistent", "Triggered By", "Inconsistency Message"]
    assert list(edges.columns)[2] == "Edge" and len(edges.columns) == 10


def test_without_atom_trace_an_ipl_row_keeps_its_ipl_name_and_a_conflict_loses_its_message() -> None:
    pr.settings.atom_trace = False
    pr.add_inconsistent_predicate("sick", "healthy")
    g = nx.DiGraph()
    g.add_nodes_from(["Alice", "Bob"])
    pr.load_graph(g)
    pr.add_rule(pr.Rule("rested(x) <- healthy(x)", "rest_rule"))
    pr.add_fact(pr.Fact("sick(Bob):[0.8,1.0]", "bob_sick", 0, 0))
    pr.add_fact(pr.Fact("sick(Alice):[0.8,1.0]", "alice_sick", 0, 0))
    pr.add_fact(pr.Fact("healthy(Alice):[0.9,1.0]", "alice_healthy", 0, 0))
    nodes, _ = pr.get_rule_trace(pr.reason(timesteps=0))
    rows = nodes[["Node", "Label", "Old Bound", "Occurred Due To", "Consistent", "Triggered By",
                  "Inconsistency Message"]].values.tolist()
    assert ["Bob", "healthy", "-", "IPL: sick", True, "IPL", ""] in rows  # PyReason: f'IPL: {l}'
    conflicts = [r for r in rows if not r[4]]
    assert conflicts and all(r[3] == "-" and r[6] == "" for r in conflicts)  # actual_name, msg: atom_trace only
