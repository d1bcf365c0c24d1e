"""why / why-not on real engine traces (tests/data/store_walk.rules, see store_helpers.write_walk_run)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from store_helpers import write_walk_run

from tracelab.cli import main
from tracelab.store.reader import open_run
from tracelab.store.why import WhyNode, explain, explain_change, render_why, render_why_not, why_not


@pytest.fixture(scope="module")
def con(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201 - a duckdb connection
    return open_run(write_walk_run(tmp_path_factory.mktemp("why") / "walk"))


ADVANCED = Path(__file__).resolve().parent.parent / "sample_runs" / "advanced"


def child(node: WhyNode, atom: str) -> WhyNode:
    matches = [c for c in node.children if c.atom == atom]
    assert len(matches) == 1, [c.atom for c in node.children]
    return matches[0]


def test_why_an_immediate_rule_fired_down_to_facts_and_actions(con) -> None:  # noqa: ANN001
    tree = explain(con, 10, "alarm(r1)", at=4)
    assert (tree.atom, tree.value, tree.t, tree.pass_no) == ("alarm(r1)", [1.0, 1.0], 3, 1)
    assert (tree.cause.kind, tree.cause.name, tree.cause.immediate) == ("rule", "alarm", True)
    assert tree.cause.bindings == {"A": "r1", "X": "c"}
    assert [c.clause for c in tree.children] == ["agent(r1):[1,1]", "at(r1,c):[1,1]", "danger(c):[1,1]"]
    assert all(c.holds for c in tree.children)
    agent = child(tree, "agent(r1)")
    assert agent.cause.kind == "fact" and agent.cause.text == "agent(r1):[1,1]" and not agent.children
    # at(r1,c) came from the delayed rule go at t=3, which read its body at the end of t=2 ...
    at_c = child(tree, "at(r1,c)")
    assert (at_c.t, at_c.cause.name, at_c.cause.delay) == (3, "go", 1)
    assert at_c.cause.reads == "body read at the end of t=2"
    at_b = child(at_c, "at(r1,b)")
    assert (at_b.value, at_b.t, at_b.cause.name) == ([1.0, 1.0], 2, "go")
    # ... which in turn read the end of t=1: the start cell (a fact) and the agent's action
    assert child(at_b, "at(r1,a)").cause.kind == "fact"
    move = child(at_b, "move(r1)")
    assert (move.t, move.cause.kind, move.cause.name) == (1, "action", "action")
    # the same action is used again by the later move: shown once, then referred to
    again = child(at_c, "move(r1)")
    assert again.repeated and not again.children


def test_a_delayed_rule_sees_its_body_as_it_was_when_read(con) -> None:  # noqa: ANN001
    # at t=3 `leave` cleared at(r1,b); it read at(r1,b) = [1,1] at the end of t=2, not today's [0,0]
    tree = explain(con, 10, "at(r1,b)", at=5)
    assert (tree.value, tree.t, tree.cause.name) == ([0.0, 0.0], 3, "leave")
    body = child(tree, "at(r1,b)")
    assert body.value == [1.0, 1.0] and body.holds and body.t == 2
    assert child(tree, "move(r1)").value == [1.0, 1.0]


def test_an_ordinary_zero_delay_rule_reads_before_its_pass(con) -> None:  # noqa: ANN001
    tree = explain(con, 10, "near(r1,c)", at=2)
    assert (tree.t, tree.pass_no, tree.cause.name, tree.cause.delay) == (2, 1, "near", 0)
    assert tree.cause.reads == "body read before ordinary pass 1 of t=2"
    at_b = child(tree, "at(r1,b)")
    assert (at_b.t, at_b.pass_no, at_b.cause.name) == (2, 0, "go")


def test_every_rule_row_of_the_run_has_a_body_that_held_when_read(con) -> None:  # noqa: ANN001
    """For each change made by a rule, why() must find every body clause satisfied at its read point."""
    rows = con.execute("SELECT episode, atom, t, seq FROM changes c WHERE cause_kind = 2 AND seq = "
                       "(SELECT max(seq) FROM raw.changes d WHERE d.episode = c.episode AND d.atom = c.atom_id "
                       "AND d.t = c.t)").fetchall()
    assert len(rows) > 10
    for episode, atom, t, seq in rows:
        tree = explain(con, episode, atom, at=t, depth=1)
        assert tree.seq == seq and tree.children
        assert all(c.holds for c in tree.children), render_why(tree, t)


def test_why_of_a_change_is_that_rows_derivation(con) -> None:  # noqa: ANN001
    """explain_change roots the tree at the given row: its own rule, grounding and bound."""
    rows = con.execute("SELECT episode, seq, rule, new_lower, new_upper, grounding FROM changes "
                       "WHERE cause_kind = 2 ORDER BY episode, seq").fetchall()
    for episode, seq, rule, lo, up, grounding in rows:
        tree = explain_change(con, episode, seq, depth=1)
        assert (tree.seq, tree.cause.name, tree.value, tree.cause.grounding) == (seq, rule, [lo, up], grounding)
        assert tree.children and all(c.holds for c in tree.children), render_why(tree)
    with pytest.raises(KeyError, match="episode 10 has no change row with seq 999999"):
        explain_change(con, 10, 999999)


def test_why_of_a_change_its_atom_undid_later_in_the_step() -> None:
    """In the game, immediate rules cascade in passes: acting(clock) is cleared by clr_acting in pass 0
    and set again by p_act in pass 1 of the same step. Each row's tree is its own rule's, not the bound
    at the end of the step."""
    con = open_run(ADVANCED)
    twice = con.execute("SELECT c.seq, c.rule, c.new_lower, c.new_upper FROM changes c WHERE c.episode = 0 "
                        "AND c.cause_kind = 2 AND c.seq < (SELECT max(seq) FROM raw.changes d WHERE "
                        "d.episode = 0 AND d.atom = c.atom_id AND d.t = c.t) ORDER BY c.seq LIMIT 12").fetchall()
    assert twice, "the sample run has atoms changed twice within a step"
    for seq, rule, lo, up in twice:
        tree = explain_change(con, 0, seq, depth=2)
        assert (tree.seq, tree.cause.name, tree.value) == (seq, rule, [lo, up])
        end = explain(con, 0, tree.atom, at=tree.t, depth=1)      # the bound at the end of the step
        assert end.seq != seq and end.seq > seq
        assert all(c.holds for c in tree.children), render_why(tree)


def test_atom_never_set_depth_limit_json_and_text(con) -> None:  # noqa: ANN001
    never = explain(con, 11, "alarm(r1)", at=5)
    assert never.value == [0.0, 1.0] and never.cause.kind == "default" and never.t is None
    shallow = explain(con, 12, "at(r1,d)", at=5, depth=1)
    assert shallow.children and all(not c.children for c in shallow.children)
    assert child(shallow, "at(r1,c)").truncated
    doc = json.loads(json.dumps(shallow.to_dict()))
    assert doc["cause"]["name"] == "go" and len(doc["children"]) == 3
    text = render_why(explain(con, 10, "alarm(r1)", at=4), 4)
    assert text.splitlines()[0].startswith("alarm(r1) = [1,1] at the end of t=4: set at t=3 pass 1")
    assert "├─ ok at(r1,c):[1,1] = [1,1]: set at t=3 pass 0 [0,1]->[1,1] by go (Δt=1" in text
    assert "[explained above]" in text


def test_why_errors_name_the_offending_value(con) -> None:  # noqa: ANN001
    with pytest.raises(KeyError, match="no node 'zz'"):
        explain(con, 10, "at(r1,zz)", at=3)
    with pytest.raises(KeyError, match="no label 'flies'"):
        explain(con, 10, "flies(r1)", at=3)
    with pytest.raises(KeyError, match="episode 99 has no trace rows.*10, 11, 12"):
        explain(con, 99, "at(r1,a)", at=3)
    with pytest.raises(ValueError, match="not ground"):
        explain(con, 10, "at(r1,X)", at=3)


def test_why_not_reports_the_first_failed_clause(con) -> None:  # noqa: ANN001
    # episode 10 stopped at t=3, so `go` did not move r1 on at t=4: move(r1) was [0,0] at the end of t=3
    w = why_not(con, 10, "go", {"A": "r1"}, at=4)
    assert w.reads_at == 3 and w.bindings == {"A": "r1", "X": "c", "Y": "d"}
    assert [c.holds for c in w.checks] == [True, True, False]
    failed = w.checks[w.failed]
    assert (failed.clause, failed.value, failed.set_at, failed.set_by) == ("move(r1):[1,1]", [0.0, 0.0], 3, "action")
    assert render_why_not(w).splitlines()[-1] == "first failed clause: #3 move(r1):[1,1] (move(r1) = [0,0])"
    # episode 12 kept moving: the same question finds the rule active
    ok = why_not(con, 12, "go", {"A": "r1"}, at=4)
    assert ok.failed is None and ok.head == "at(r1,d)" and ok.head_value == [1.0, 1.0]
    # a Δt=0 rule is read at the end of `at` itself; danger(b) was never set
    w = why_not(con, 10, "alarm", {"A": "r1"}, at=2)
    assert w.reads_at == 2 and w.checks[w.failed].atom == "danger(b)" and w.checks[w.failed].value == [0.0, 1.0]


def test_why_not_with_an_open_pattern_and_bad_input(con) -> None:  # noqa: ANN001
    w = why_not(con, 10, "go", {"X": "d"}, at=5)
    assert w.failed == 0 and w.checks[0].atom is None
    assert "no atom matching at(A,d):[1,1] holds at the end of t=4" in w.checks[0].note
    with pytest.raises(KeyError, match="no variable\\(s\\) \\['Z'\\].*A, Y, X"):
        why_not(con, 10, "go", {"Z": "a"}, at=3)
    with pytest.raises(KeyError, match="no rule 'gone' in this run; did you mean go"):
        why_not(con, 10, "gone", {}, at=3)
    with pytest.raises(KeyError, match="no node 'q'"):
        why_not(con, 10, "go", {"A": "q"}, at=3)


def test_why_reads_the_sealed_form_the_same_way(tmp_path: Path) -> None:
    from tracelab.store.seal import seal_run
    run = write_walk_run(tmp_path / "walk")
    live = explain(open_run(run), 10, "alarm(r1)", at=4).to_dict()
    assert explain(open_run(seal_run(run)), 10, "alarm(r1)", at=4).to_dict() == live


CLOSED_RULES = Path(__file__).resolve().parent / "data" / "store_closed.rules"


@pytest.fixture(scope="module")
def closed_con(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201 - a duckdb connection
    return open_run(write_walk_run(tmp_path_factory.mktemp("why") / "closed", rules=CLOSED_RULES))


def test_why_reads_a_closed_predicates_unset_atom_as_false(closed_con) -> None:  # noqa: ANN001
    # shielded(a) was never set; %closed reads it as [0,0], so ~shielded(a) held when `exposed` fired
    tree = explain(closed_con, 10, "exposed(r1,a)", at=0)
    assert (tree.value, tree.cause.name) == ([1.0, 1.0], "exposed")
    shield = child(tree, "shielded(a)")
    assert shield.value == [0.0, 1.0] and shield.holds and shield.clause_closed and shield.t is None
    assert "ok ~shielded(a):[1,1] = [0,1]: never set (the default [0,1], read as [0,0]: %closed)" in render_why(tree, 0)
    # a non-closed clause of the same rule keeps its usual reading
    assert not child(tree, "agent(r1)").clause_closed


def test_every_rule_row_of_a_closed_program_has_a_body_that_held(closed_con) -> None:  # noqa: ANN001
    rows = closed_con.execute("SELECT episode, atom, t FROM changes WHERE cause_kind = 2").fetchall()
    assert {a for _, a, _ in rows} >= {"exposed(r1,a)", "exposed(r1,c)"}
    for episode, atom, t in rows:
        tree = explain(closed_con, episode, atom, at=t, depth=1)
        assert tree.children and all(c.holds for c in tree.children), render_why(tree, t)


def test_why_not_on_a_closed_predicate(closed_con) -> None:  # noqa: ANN001
    # r1 stood on the shielded cell b at t=2: exposed(r1,b) never held, and why-not says which clause
    w = why_not(closed_con, 10, "exposed", {"A": "r1", "X": "b"}, at=2)
    assert w.checks[w.failed].atom == "shielded(b)" and w.checks[w.failed].value == [1.0, 1.0]
    # on cell a the unset shielded(a) holds its negation, read the closed way
    ok = why_not(closed_con, 10, "exposed", {"A": "r1", "X": "a"}, at=0)
    assert ok.failed is None and ok.checks[-1].closed
    assert "shielded(a) = [0,1] (never set, read as [0,0]: %closed)" in render_why_not(ok)
    # with X open, the search enumerates at(r1,X) and tests ~shielded(X) without enumerating it
    open_x = why_not(closed_con, 10, "exposed", {"A": "r1"}, at=3)
    assert open_x.failed is None and open_x.bindings["X"] == "c"


def test_a_run_written_before_the_closed_column_reads_as_not_closed(tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    from tracelab.store.model import RunModel
    run = write_walk_run(tmp_path / "old", rules=CLOSED_RULES)
    parts = sorted((run / "parts").rglob("*.parquet"))
    clause_parts = [p for p in parts if "clauses" in p.parts]
    assert clause_parts
    for part in clause_parts:  # the table as the earlier release wrote it
        table = pq.read_table(part)
        pq.write_table(table.drop_columns(["closed"]), part)
    model = RunModel(open_run(run))
    assert [c.closed for c in model.rule("exposed").body] == [False, False, False]
    fresh = RunModel(open_run(write_walk_run(tmp_path / "new", rules=CLOSED_RULES)))
    assert [c.closed for c in fresh.rule("exposed").body] == [False, False, True]


def test_a_declared_worlds_external_facts_say_what_set_them(tmp_path: Path) -> None:
    """why names an external fact's setter from the run's declared_facts: the agent's action, a named
    draw, the start; a run that does not declare them reads every one as `action`."""
    run = tmp_path / "lake"
    assert main(["play", "--env", "tracelab/FrozenLake-v1", "--episodes", "3", "--seed", "0", "--run", str(run)]) == 0
    con = open_run(run)
    try:
        slip_t, slip = con.execute("SELECT t, atom FROM changes WHERE episode = 0 AND label = 'slip' AND new_lower = 1 "
                                   "ORDER BY t LIMIT 1").fetchone()
        key_t, key = con.execute("SELECT t, atom FROM changes WHERE episode = 0 AND label = 'pressed' "
                                 "AND new_lower = 1 ORDER BY t LIMIT 1").fetchone()
        whys = [render_why(explain(con, 0, atom, t, depth=1)) for atom, t in ((slip, slip_t), (key, key_t),
                                                                            ("at(c0_0)", 0))]
    finally:
        con.close()
    assert whys[0].splitlines()[0].endswith("by draw:slip"), whys[0]
    assert whys[1].splitlines()[0].endswith("by action"), whys[1]
    assert whys[2].splitlines()[0].endswith("by draw:start"), whys[2]  # [[start.choose]] named start
