"""The compiled engine's API: batching, stepping, interning, tracing, errors, compile-once."""
from __future__ import annotations

import json

import numpy as np
import pytest
from tracelab.engine import (
    CAUSE_EXTERNAL,
    CAUSE_FACT,
    CAUSE_POLICY,
    CAUSE_RULE,
    TRACE_COLUMNS,
    Engine,
    FixpointError,
    InconsistencyError,
    ProgramCheckError,
    kernel,
    parse_program,
)

from tracelab.cli import main as cli_main

CHAIN = """
edge(a,b) static
edge(b,c) static
edge(c,d) static
spread: reach(Y) <-1 reach(X), edge(X,Y)
mark:   seen(X) <-0 reach(X)
"""


def rows(eng: Engine) -> list[tuple]:
    tr = eng.take_trace()
    return [(int(tr["world"][i]), int(tr["t"][i]), eng.atom_text(int(tr["atom"][i])),
             eng.cause_name(int(tr["cause_kind"][i]), int(tr["cause_id"][i])))
            for i in range(len(tr["t"]))]


def test_worlds_in_a_batch_evolve_independently():
    eng = Engine(parse_program(CHAIN), worlds=3)
    eng.add_fact(eng.atom("reach", "a"), world=0)
    eng.add_fact(eng.atom("reach", "c"), world=2)
    eng.run(4)  # reach(a) at t=0 reaches d at t=3
    assert eng.query("reach(d)", 0) == (1.0, 1.0)
    assert eng.query("reach(b)", 0) == (1.0, 1.0)
    assert eng.query("reach(b)", 2) == (0.0, 1.0)  # world 2 started further along the chain
    assert eng.query("reach(d)", 2) == (1.0, 1.0)
    assert eng.interpretation(1) == {"edge(a,b)": (1, 1), "edge(b,c)": (1, 1), "edge(c,d)": (1, 1)}


def test_delayed_rule_fires_at_t_plus_delta_and_trace_names_it():
    eng = Engine(parse_program(CHAIN))
    eng.add_fact(eng.atom("reach", "a"))
    eng.run(3)
    got = rows(eng)
    assert (0, 0, "reach(a)", "external") in got
    assert (0, 1, "reach(b)", "spread") in got
    assert (0, 2, "reach(c)", "spread") in got
    assert (0, 0, "seen(a)", "mark") in got
    assert not any(r[2] == "reach(b)" and r[1] == 0 for r in got)


def test_trace_columns_and_dtypes_and_clearing():
    eng = Engine(parse_program(CHAIN))
    eng.add_fact(eng.atom("reach", "a"))
    eng.step()
    tr = eng.take_trace()
    assert tuple(tr) == TRACE_COLUMNS
    assert tr["cause_kind"].dtype == np.int8 and tr["old_lower"].dtype == np.float64
    assert set(tr["cause_kind"].tolist()) == {CAUSE_FACT, CAUSE_EXTERNAL, CAUSE_RULE}
    assert len(eng.take_trace()["t"]) == 0


def test_tracing_off_and_sampled_per_world_gives_same_interpretation():
    on = Engine(parse_program(CHAIN), worlds=2, trace=True)
    sampled = Engine(parse_program(CHAIN), worlds=2, trace=[False, True])
    off = Engine(parse_program(CHAIN), worlds=2, trace=False)
    for eng in (on, sampled, off):
        eng.add_fact(eng.atom("reach", "a"))
        eng.run(4)
    assert len(off.take_trace()["t"]) == 0
    assert set(sampled.take_trace()["world"].tolist()) == {1}
    assert on.interpretation(0) == sampled.interpretation(0) == off.interpretation(0)
    np.testing.assert_array_equal(on.lower, off.lower)


def test_external_fact_on_a_new_atom_grows_groundings_mid_run():
    eng = Engine(parse_program(CHAIN))
    eng.run(2)
    before = len(eng.groundings.rule)
    eng.add_fact(eng.atom("edge", "d", "zz"), static=True)  # a node the program never named
    eng.add_fact(eng.atom("reach", "c"))
    eng.run(3)
    assert len(eng.groundings.rule) > before
    assert eng.query("reach(zz)") == (1.0, 1.0)


def test_grounding_table_matches_rule_variables():
    prog = parse_program(CHAIN)
    eng = Engine(prog)
    eng.add_fact(eng.atom("reach", "a"))
    eng.run(2)
    tr = eng.take_trace()
    i = int(np.flatnonzero((tr["cause_kind"] == CAUSE_RULE) & (tr["t"] == 1))[0])
    g = int(tr["grounding"][i])
    assert eng.rules[eng.groundings.rule[g]].name == "spread"
    assert eng.grounding_text(g) == "Y=b, X=a"
    assert [eng.atom_text(int(a)) for a in eng.groundings.body(g)] == ["reach(a)", "edge(a,b)"]


def test_true_join_does_not_mix_bindings_across_components():
    # p(X), q(X,Y), r(Y): a per-variable candidate set would take X=a (from component 1) and Y=d
    # (from component 2); the join has no binding with both, so h must stay unset.
    prog = parse_program("""
    p(a) static
    q(a,b) static
    q(c,d) static
    r(d) static
    j: h(X) <-0 p(X), q(X,Y), r(Y)
    """)
    eng = Engine(prog)
    eng.run(2)
    assert eng.query("h(a)") == (0.0, 1.0)


def test_immediate_rules_apply_one_at_a_time_in_rule_order():
    # `pick` fires for its lowest grounding (X=a); then `close`, earlier in the file than `pick`, fires
    # before pick's next grounding and disables it. With the two rules swapped both picks would fire.
    prog = parse_program("""
    %mode override
    cand(a)
    cand(b)
    done(x):[0,0]
    close: done(x) <-! pick(X)
    pick: pick(X) <-! cand(X), done(x):[0,0]
    """)
    eng = Engine(prog)
    eng.step()
    assert eng.query("pick(a)") == (1.0, 1.0)
    assert eng.query("pick(b)") == (0.0, 1.0)


def test_abort_policy_names_atom_time_and_both_sources():
    prog = parse_program("""
    %inconsistency abort
    p(a) @0..9
    flip: p(X):[0,0] <-2 p(X)
    """, file="abort.rules")
    eng = Engine(prog)
    eng.run(2)
    with pytest.raises(InconsistencyError) as e:
        eng.run(1)
    msg = str(e.value)
    assert "p(a)" in msg and "t=2" in msg and "fact" in msg and "rule flip" in msg and "X=a" in msg


def test_policy_rows_carry_the_policy():
    prog = parse_program("""
    %inconsistency hull
    p(a):[0.8,1]
    low: p(X):[0,0.2] <-1 p(X):[0.5,1]
    """)
    eng = Engine(prog)
    eng.run(2)
    assert eng.query("p(a)") == (0.0, 1.0)
    tr = eng.take_trace()
    assert CAUSE_POLICY in tr["cause_kind"].tolist()


def test_oscillation_raises_fixpoint_error():
    prog = parse_program("""
    %mode override
    p(a)
    on:  p(X) <-0 p(X):[0,0]
    off: p(X):[0,0] <-0 p(X)
    """)
    eng = Engine(prog, max_passes=50)
    with pytest.raises(FixpointError, match="t=0"):
        eng.step()


def test_bad_external_bound_names_the_value():
    eng = Engine(parse_program(CHAIN))
    with pytest.raises(ValueError, match=r"\[0.7,0.2\].*reach\(a\)"):
        eng.add_fact(eng.atom("reach", "a"), 0.7, 0.2)


def test_external_rows_step_worlds_and_unsettable_atoms_are_refused_before_any_change():
    eng = Engine(parse_program(CHAIN), worlds=2)
    reach_a, reach_b = eng.atom("reach", "a"), eng.atom("reach", "b")
    eng.add_facts(np.array([reach_a]), 0.0, 1.0)  # made settable once, as a simulator does
    eng.step()
    eng.take_trace()
    first = eng.next_external_id()
    ptr = np.array([0, 1, 1], np.int64)  # one row, for world 0
    eng.step(external=(ptr, np.array([[reach_a, 0, first]], np.int64), np.array([[1.0, 1.0]])))
    assert eng.query("reach(a)", 0) == (1.0, 1.0) and eng.query("reach(a)", 1) == (0.0, 1.0)
    assert eng.next_external_id() == first + 1
    assert rows(eng) == [(0, 1, "reach(a)", "external"), (0, 1, "seen(a)", "mark")]
    edge_da = eng.atom("edge", "d", "a")  # interned, but no fact or rule can ever set it
    t, before = eng.t, (eng.lower.copy(), eng.upper.copy())
    bad = np.array([[reach_b, 0, first + 1], [edge_da, 0, first + 2]], np.int64)
    with pytest.raises(ValueError, match=r"edge\(d,a\).*no fact or rule can set"):
        eng.step(external=(np.array([0, 1, 2], np.int64), bad, np.ones((2, 2))))
    assert eng.t == t and eng.next_external_id() == first + 1  # refused whole: no world stepped
    assert (eng.lower[:, :before[0].shape[1]] == before[0]).all()
    assert (eng.upper[:, :before[1].shape[1]] == before[1]).all()
    assert rows(eng) == []


def test_a_new_program_does_not_recompile_the_kernel():
    Engine(parse_program(CHAIN)).run(2)
    other = parse_program("""
    %timesteps reset
    %mode override
    x(a) static
    y: y(X):[0.2,0.9] <-! x(X)
    z: ~z(X):[0.5,1] <-3 y(X):[0.1,1]
    """)
    Engine(other, worlds=4).run(5)
    assert len(kernel.step_worlds.signatures) == 1


def test_reason_cli_json(tmp_path, capsys):
    f = tmp_path / "p.rules"
    f.write_text(CHAIN + "reach(a)\n")
    assert cli_main(["reason", str(f), "--steps", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["interpretation"]["reach(c)"] == [1.0, 1.0]
    assert {"t": 1, "pass": 0, "atom": "reach(b)", "old": [0.0, 1.0], "new": [1.0, 1.0],
            "cause": "spread", "grounding": "Y=b, X=a"} in out["changes"]


def test_reason_cli_reports_parse_errors_with_location(tmp_path, capsys):
    f = tmp_path / "bad.rules"
    f.write_text("p(a)\nq(X) <-0 p(X\n")
    assert cli_main(["reason", str(f), "--steps", "1"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"tracelab: error: {f}:2:") and err.count("\n") == 1


def test_restore_puts_one_world_back_and_shifts_its_schedule():
    eng = Engine(parse_program(CHAIN), worlds=2)
    eng.add_fact(eng.atom("reach", "a"))
    eng.step()
    snap = eng.snapshot()  # before t=1: reach(b) is scheduled for t=1
    eng.run(3)
    assert eng.query("reach(d)", 0) == (1.0, 1.0)
    eng.restore(snap, np.array([False, True]))
    assert eng.query("reach(b)", 1) == (0.0, 1.0) and eng.query("reach(d)", 0) == (1.0, 1.0)
    eng.step()  # world 1 replays its t=1 now, at t=4
    assert eng.query("reach(b)", 1) == (1.0, 1.0)
    assert eng.query("reach(c)", 1) == (0.0, 1.0)
    eng.run(2)
    assert eng.interpretation(1) == eng.interpretation(0)


def test_restore_after_groundings_grew_recounts():
    eng = Engine(parse_program(CHAIN), worlds=2)
    eng.add_fact(eng.atom("reach", "a"))
    eng.step()
    snap = eng.snapshot()
    eng.add_fact(eng.atom("edge", "d", "e"), static=True)
    eng.run(4)
    eng.restore(snap, np.array([1]))
    eng.run(5)
    assert eng.query("reach(d)", 1) == (1.0, 1.0)
    assert eng.query("reach(e)", 1) == (0.0, 1.0)  # edge(d,e) was added after the snapshot
    assert eng.query("reach(e)", 0) == (1.0, 1.0)


def test_an_immediate_grounding_made_active_between_steps_applies_at_the_next_one():
    """After a step that ended at its fixpoint the kernel does not look again at every active immediate
    grounding (none would apply); set_bounds and a restore change a world outside the kernel, and the
    groundings they make active apply at the world's next step, in that world only."""
    eng = Engine(parse_program("""
    node(a) static
    node(b) static
    p: p(X) <-! q(X), node(X)
    """), worlds=2)
    q = np.array([eng.atom("q", "a"), eng.atom("q", "b")])
    for world in (0, 1):  # settable, unknown: no grounding of p is active
        eng.set_bounds(q, np.zeros(2), np.ones(2), np.zeros(2, bool), world)
    eng.run(2)
    eng.set_bounds(q[1:], np.ones(1), np.ones(1), np.zeros(1, bool), world=1)
    eng.step()
    assert eng.query("p(b)", 1) == (1.0, 1.0) and eng.query("p(b)", 0) == (0.0, 1.0)
    eng.set_bounds(q[:1], np.ones(1), np.ones(1), np.zeros(1, bool), world=0)
    snap = eng.snapshot()  # not a fixpoint: p(a) applies at world 0's next step
    eng.step()
    assert eng.query("p(a)", 0) == (1.0, 1.0) and eng.query("p(a)", 1) == (0.0, 1.0)
    eng.restore(snap, np.array([1]), source=np.array([0]))
    eng.step()
    assert eng.query("p(a)", 1) == (1.0, 1.0)


def test_a_rule_with_too_many_binding_clauses_is_refused_by_name():
    body = ", ".join(f"p{i}(X)" for i in range(128))
    with pytest.raises(ProgramCheckError, match="<string>:1:1: .*rule 'big' has 128 binding body clauses; "
                                                "the engine allows at most 127"):
        parse_program(f"big: q(X) <-0 {body}\np0(a)")


def test_trace_buffer_grows_between_worlds_and_keeps_every_row():
    # 40 worlds, each writing more rows per step than the smallest room; every world's rows arrive in order
    prog = "\n".join(f"c{i}: n{i}(X) <-0 n{i - 1}(X)" for i in range(1, 30)) + "\nn0(a)"
    eng = Engine(parse_program(prog), worlds=40, trace=True, trace_rows_per_step=8)
    eng.step()
    tr = eng.take_trace()
    assert len(tr["t"]) == 40 * 30
    assert np.all(np.diff(tr["world"]) >= 0)
    assert eng.interpretation(39)["n29(a)"] == (1.0, 1.0)


@pytest.mark.parametrize("arrow", ["<-!", "<-0"])
def test_the_trace_buffer_grows_inside_a_step(arrow):
    # the buffer starts with 1024 rows: a chain of 1100 immediate (or ordinary) rules overflows it in one
    # step of world 1, and 3000 facts overflow it in pass 0; the worlds resume where they stopped
    prog = "\n".join(f"c{i}: n{i}(X) {arrow} n{i - 1}(X)" for i in range(1, 1100)) + "\nn0(a)\n" + \
        "\n".join(f"f{i}(a)" for i in range(3000))
    eng = Engine(parse_program(prog), worlds=2, trace=[False, True], trace_rows_per_step=8, kernel="counting",
                 max_passes=2000)
    eng.step()
    tr = eng.take_trace()
    assert len(tr["t"]) == 1100 + 3000 and set(tr["world"].tolist()) == {1}
    names = [eng.atom_text(int(a)) for a in tr["atom"]]
    assert names[:3001] == sorted(names[:3001], key=lambda x: eng.atom(x.split("(")[0], "a"))
    assert names[3001:] == [f"n{i}(a)" for i in range(1, 1100)]  # the chain, in order, after pass 0
    assert tr["pass_no"][-1] == (1 if arrow == "<-!" else 1099)
    assert eng.interpretation(0) == eng.interpretation(1)
    assert eng.stats["changes"].tolist() == [4100, 4100]


def test_schedule_grows_mid_batch_and_every_world_keeps_its_firings():
    # each world schedules 60 delayed firings per step, more than the schedule's first room
    prog = "\n".join(f"n{i}(a)" for i in range(60)) + "\nlater: m(X) <-1 n(X)\n" + \
        "\n".join(f"d{i}: m{i}(X) <-1 n{i}(X)" for i in range(60))
    eng = Engine(parse_program(prog), worlds=3, trace=True)
    eng.run(2)
    for w in range(3):
        got = eng.interpretation(w)
        assert all(got[f"m{i}(a)"] == (1.0, 1.0) for i in range(60)), w
    assert {r[3] for r in rows(eng) if r[1] == 1} == {f"d{i}" for i in range(60)}


def _spread_traces(handover_rows: int, monkeypatch: pytest.MonkeyPatch) -> list[dict[str, np.ndarray]]:
    """Trace columns of 3 steps of the spread rule over a 70k-edge graph (t = 0 writes 70k rows)."""
    import tracelab.engine.core as core
    from tracelab.engine import Graph
    monkeypatch.setattr(core, "TRACE_HANDOVER_ROWS", handover_rows)
    rng = np.random.default_rng(1)
    n, m = 14_000, 70_000
    args = np.column_stack([rng.integers(0, n, m), rng.integers(0, n, m)]).astype(np.int32)
    args = np.concatenate([[[0, -1], [1, -1]], args]).astype(np.int32)  # two infected seeds, then links
    labels = np.array([0, 0] + [1] * m, np.int32)
    bounds = np.ones((m + 2, 2))
    graph = Graph([f"n{i}" for i in range(n)], ["infected", "link"], [1, 2], labels, args, bounds)
    eng = Engine(parse_program("spread: infected(X) <-1 infected(Y), link(Y,X)\n"), graph, trace=True)
    out = []
    for _ in range(3):
        eng.step()
        out.append(eng.take_trace())
    return out


def test_a_big_step_hands_its_trace_buffer_over_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    handed = _spread_traces(65_536, monkeypatch)  # t = 0's rows are handed over, later steps copied
    copied = _spread_traces(10**9, monkeypatch)  # every step copied out of the buffer
    assert len(handed[0]["t"]) > 65_536 and len(handed[1]["t"]) > 0
    for a, b in zip(handed, copied):  # later steps did not write into the columns handed over before
        assert a.keys() == b.keys()
        for name in a:
            assert a[name].dtype == b[name].dtype and np.array_equal(a[name], b[name]), name


def test_set_bounds_carries_an_interpretation_and_the_rules_read_it():
    # an interpretation from elsewhere (tracelab.pyreason's reason(again=True) with new rules): the atoms
    # take their bounds, static ones stay frozen, and the groundings that read them are counted again
    eng = Engine(parse_program(CHAIN + "%timesteps reset\n"))
    eng.step()
    assert eng.query("seen(a)") == (0.0, 1.0)
    atoms = np.array([eng.atom("reach", "a"), eng.atom("seen", "d")])
    eng.set_bounds(atoms, np.array([1.0, 0.0]), np.array([1.0, 0.0]), np.array([True, True]))
    eng.take_trace()
    eng.step()  # reach(a) is static through the reset: mark reads it at once, spread one step later
    assert eng.query("seen(a)") == (1.0, 1.0) and eng.query("reach(a)") == (1.0, 1.0)
    eng.step()
    assert eng.query("reach(b)") == (1.0, 1.0)
    assert eng.query("seen(d)") == (0.0, 0.0)  # frozen: no rule or reset moves it
