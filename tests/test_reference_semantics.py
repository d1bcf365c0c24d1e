"""The semantics of docs/language.md, pinned one point at a time on the reference evaluator.

Each test is a small program whose outcome is worked out by hand in its comments; the compiled engine is
then held to the reference by tests/test_engine_vs_reference.py.
"""
from __future__ import annotations

import dataclasses

import pytest
from hypothesis import HealthCheck, given, settings
from strategies import Scenario, scenarios
from tracelab.engine.errors import FixpointError, InconsistencyError
from tracelab.engine.parser import parse_program
from tracelab.engine.program import Fact, Literal, Term
from tracelab.engine.reference import (
    CAUSE_EXTERNAL,
    CAUSE_FACT,
    CAUSE_POLICY,
    CAUSE_RESET,
    CAUSE_RULE,
    FULL,
    RefChange,
    ReferenceEvaluator,
    atom_text,
)

Interp = dict[str, tuple[float, float]]


def evaluator(text: str, **kw: object) -> ReferenceEvaluator:
    return ReferenceEvaluator(parse_program(text, "<test>"), **kw)


def run(text: str, steps: int = 1, **kw: object) -> ReferenceEvaluator:
    ev = evaluator(text, **kw)
    for _ in range(steps):
        ev.step()
    return ev


def interp(ev: ReferenceEvaluator) -> Interp:
    return {atom_text(a): iv for a, iv in ev.interpretation().items()}


def history(text: str, steps: int, **kw: object) -> list[Interp]:
    """The interpretation after each step."""
    ev = evaluator(text, **kw)
    out = []
    for _ in range(steps):
        ev.step()
        out.append(interp(ev))
    return out


def rows(ev: ReferenceEvaluator, atom: str | None = None, t: int | None = None) -> list[RefChange]:
    return [c for c in ev.changes if (atom is None or atom_text(c.atom) == atom) and (t is None or c.t == t)]


# ---- satisfaction --------------------------------------------------------------------------------

def test_containment_is_satisfaction() -> None:
    ev = run("""
    p(a):[0.5,1]
    wide(X) <-0 p(X):[0.25,1]      # [0.5,1] ⊆ [0.25,1]
    exact(X) <-0 p(X):[0.5,1]      # equal bounds contain each other
    narrow(X) <-0 p(X):[0.75,1]    # 0.5 < 0.75: not contained
    inner(X) <-0 p(X):[0.5,0.75]   # 1 > 0.75: not contained (overlap is not enough)
    """)
    assert interp(ev) == {"p(a)": (0.5, 1.0), "wide(a)": (1.0, 1.0), "exact(a)": (1.0, 1.0)}


def test_unset_atoms_are_0_1_and_only_satisfy_0_1() -> None:
    ev = run("""
    a(x)
    any(X) <-0 a(X), p(X):[0,1]       # [0,1] ⊆ [0,1]: holds for the never-set p(x)
    false(X) <-0 a(X), p(X):[0,0]     # an unset atom is not false
    true(X) <-0 a(X), p(X)            # nor true
    notp(X) <-0 a(X), ~p(X)           # complement of [0,1] is [0,1]: not [1,1]
    """)
    assert interp(ev) == {"a(x)": (1.0, 1.0), "any(x)": (1.0, 1.0)}
    assert ev.bound(("p", ("x",))) == FULL
    assert ("p", ("x",)) not in ev.interpretation()  # interpretation() lists only atoms that are not [0,1]


def test_complement_in_body() -> None:
    ev = run("""
    p(a):[0.75,1]
    p(b):[0.5,1]
    p(c):[0,0]
    low(X) <-0 ~p(X):[0,0.25]   # complement [1-u,1-l]: a -> [0,0.25] yes, b -> [0,0.5] no
    nope(X) <-0 ~p(X)           # ~p:[1,1] needs p = [0,0]: only c
    """)
    got = interp(ev)
    assert got["low(a)"] == (1.0, 1.0) and "low(b)" not in got and "low(c)" not in got
    assert got["nope(c)"] == (1.0, 1.0) and "nope(a)" not in got and "nope(b)" not in got


def test_complement_in_head_and_fact() -> None:
    ev = run("""
    p(a)
    ~q(a):[0,0.25]                  # a fact ~q:[l,u] sets q to [1-u,1-l]
    ~r(X):[0.25,0.5] <-0 p(X)       # so does a rule head
    """)
    assert interp(ev) == {"p(a)": (1.0, 1.0), "q(a)": (0.75, 1.0), "r(a)": (0.5, 0.75)}


# ---- update modes --------------------------------------------------------------------------------

@pytest.mark.parametrize("mode, at1", [("intersection", (0.5, 0.75)), ("override", (0.0, 0.75))])
def test_program_mode_intersection_vs_override(mode: str, at1: tuple[float, float]) -> None:
    hist = history(f"""
    %mode {mode}
    p(a):[0.5,1] @0
    p(a):[0,0.75] @1
    """, 2)
    assert hist[0] == {"p(a)": (0.5, 1.0)}
    assert hist[1] == {"p(a)": at1}


@pytest.mark.parametrize("program_mode, option, expected", [
    ("intersection", "", (0.5, 0.75)),
    ("intersection", "{override}", (0.0, 0.75)),
    ("override", "", (0.0, 0.75)),
    ("override", "{intersection}", (0.5, 0.75)),
])
def test_rule_mode_option(program_mode: str, option: str, expected: tuple[float, float]) -> None:
    ev = run(f"""
    %mode {program_mode}
    p(a):[0.5,1]
    trig(a)
    set: p(X):[0,0.75] <-0 trig(X) {option}
    """)
    assert interp(ev)["p(a)"] == expected


def test_override_and_intersection_sources_together() -> None:
    # base = Mo = [0.25,1] (the fact's [0.75,1] is overridden), result = base ∩ Mi = [0.25,0.5]
    ev = run("""
    p(a):[0.75,1]
    trig(a)
    o: p(X):[0.25,1] <-0 trig(X) {override}
    i: p(X):[0,0.5] <-0 trig(X) {intersection}
    """)
    assert interp(ev)["p(a)"] == (0.25, 0.5)
    (row,) = rows(ev, "p(a)", 0)[1:]
    # the row names the first source in source order (rule o) and counts both
    assert (row.pass_no, row.cause_kind, row.cause_id, row.grounding, row.n_sources) == (1, CAUSE_RULE, 0, ("a",), 2)


def test_external_facts_take_the_program_mode() -> None:
    ev = evaluator("%mode override\np(a):[0.5,1]\n")
    ev.step()
    ev.add_fact("p", ("a",), 0.0, 0.25)
    ev.step()
    assert interp(ev) == {"p(a)": (0.0, 0.25)}  # intersection would have been inconsistent


# ---- static atoms ----------------------------------------------------------------------------------

def test_static_fact_ignores_every_later_update() -> None:
    ev = run("""
    %timesteps reset
    blocked(c):[0,0] static
    trig(c) @0..2
    blocked(c):[1,1] @1
    unblock: blocked(X):[1,1] <-0 trig(X)
    """, 3)
    assert ev.bound(("blocked", ("c",))) == (0.0, 0.0)
    # one row: the static fact itself; the rule, the later fact and the resets leave no trace (and no policy)
    assert [(c.t, c.cause_kind) for c in rows(ev, "blocked(c)")] == [(0, CAUSE_FACT)]
    assert ev.is_static(("blocked", ("c",)))


def test_static_fact_combines_with_other_pass0_sources_then_freezes() -> None:
    ev = run("""
    p(a):[0,0.5] static
    p(a):[0.25,1]
    p(a):[1,1] @1
    """, 2)
    (row,) = rows(ev, "p(a)")
    assert (row.new, row.cause_id, row.n_sources) == ((0.25, 0.5), 0, 2)
    assert interp(ev) == {"p(a)": (0.25, 0.5)}  # the fact at t=1 is ignored, not inconsistent


def test_static_fact_with_a_time_freezes_from_that_time() -> None:
    hist = history("""
    %mode override
    p(a):[0,0] @0..3
    p(a):[1,1] @1 static
    """, 3)
    # t=0: [0,0]; t=1: both facts (override): Mo = [0,0] ∩ [1,1] empty -> reset_freeze -> [0,1], frozen
    assert hist[0] == {"p(a)": (0.0, 0.0)}
    assert hist[1] == {} and hist[2] == {}


def test_static_external_fact() -> None:
    ev = evaluator("q(a)\n")
    ev.add_fact("p", ("a",), 1.0, 1.0, static=True)
    ev.step()
    ev.add_fact("p", ("a",), 0.0, 0.0)
    ev.step()
    assert interp(ev)["p(a)"] == (1.0, 1.0)
    assert [c.cause_kind for c in rows(ev, "p(a)")] == [CAUSE_EXTERNAL]


# ---- timesteps -----------------------------------------------------------------------------------

def test_persistent_timesteps_keep_the_interpretation() -> None:
    ev = run("%timesteps persistent\np(a) @0\n", 2)
    assert interp(ev) == {"p(a)": (1.0, 1.0)}
    assert rows(ev, t=1) == []


def test_reset_timesteps_reset_set_atoms_with_a_row() -> None:
    ev = run("""
    %timesteps reset
    p(a) @0
    q(a) @0..1
    """, 2)
    assert interp(ev) == {"q(a)": (1.0, 1.0)}
    assert rows(ev, "p(a)", 1) == [RefChange(1, 0, ("p", ("a",)), (1.0, 1.0), FULL, CAUSE_RESET, -1, None, 0)]
    # q(a) is reset, then set again by its fact: two rows in pass 0
    assert [(c.cause_kind, c.new) for c in rows(ev, "q(a)", 1)] == [(CAUSE_RESET, FULL), (CAUSE_FACT, (1.0, 1.0))]


# ---- groundings are true joins -------------------------------------------------------------------

JOIN = """
e(a,b)
e(c,d)
f(a)
g(d)
pair(X,Y) <-0 e(X,Y), f(X), g(Y)
src(X) <-0 e(X,Y), f(X), g(Y)
"""


def test_join_does_not_mix_bindings_across_components() -> None:
    # X in {a} and Y in {d} each satisfy some clause, but e(a,d) does not hold: no grounding at all
    # (per-variable candidate sets, PyReason's way, would fire pair(a,d) and src(a))
    ev = run(JOIN)
    assert not any(a.startswith(("pair", "src")) for a in interp(ev))


def test_join_fires_when_one_binding_satisfies_every_clause() -> None:
    ev = run(JOIN + "g(b)\n")
    got = interp(ev)
    assert got["pair(a,b)"] == (1.0, 1.0) and got["src(a)"] == (1.0, 1.0)
    assert not any(a in got for a in ("pair(a,d)", "pair(c,d)", "src(c)"))


# ---- delays ------------------------------------------------------------------------------------------

def test_delayed_rule_fires_at_t_plus_delay() -> None:
    ev = evaluator("""
    %timesteps reset
    p(a) @0
    later: q(X) <-2 p(X)
    """)
    seen = []
    for _ in range(4):
        ev.step()
        seen.append("q(a)" in interp(ev))
    assert seen == [False, False, True, False]
    (row,) = [c for c in rows(ev, "q(a)") if c.cause_kind == CAUSE_RULE]
    assert (row.t, row.pass_no, row.cause_id, row.grounding, row.n_sources) == (2, 0, 0, ("a",), 1)


def test_delayed_rule_reads_the_body_at_t() -> None:
    # p(a) is true at t=0 only; the firing lands at t=1 although p(a) is false by then
    hist = history("""
    %mode override
    %timesteps reset
    p(a) @0
    p(a):[0,0] @1
    next: q(X) <-1 p(X)
    """, 3)
    assert "q(a)" in hist[1] and "q(a)" not in hist[2]


def test_delayed_rule_reads_the_final_interpretation_of_t() -> None:
    # b(x) only exists after the fixpoint of t=0 (pass 2); the delayed rule still sees it
    ev = run("""
    %timesteps reset
    a(x) @0
    b(X) <-0 c(X)
    c(X) <-0 a(X)
    d(X) <-1 b(X)
    """, 2)
    assert interp(ev) == {"d(x)": (1.0, 1.0)}


def test_delayed_firings_join_the_pass0_sources() -> None:
    # at t=1, p(a) gets the fact, an external fact and the scheduled firing together: one row, 3 sources
    ev = evaluator("""
    q(a) @0
    p(a):[0,0.75] @1
    later: p(X):[0.5,1] <-1 q(X)
    """)
    ev.step()
    ev.add_fact("p", ("a",), 0.25, 1.0)
    ev.step()
    (row,) = rows(ev, "p(a)")
    assert (row.t, row.pass_no, row.new) == (1, 0, (0.5, 0.75))
    assert (row.cause_kind, row.cause_id, row.grounding, row.n_sources) == (CAUSE_FACT, 1, None, 3)


# ---- the Δt = 0 fixpoint -----------------------------------------------------------------------------

def test_zero_delay_rules_reach_a_fixpoint_pass_by_pass() -> None:
    # rules listed last-to-first: an ordinary pass reads the interpretation from its start, so the chain
    # still takes one pass per link
    ev = run("""
    a(x)
    d(X) <-0 c(X)
    c(X) <-0 b(X)
    b(X) <-0 a(X)
    """)
    assert [(atom_text(c.atom), c.pass_no, c.cause_id) for c in ev.changes] == [
        ("a(x)", 0, 0), ("b(x)", 1, 2), ("c(x)", 2, 1), ("d(x)", 3, 0)]


def test_ordinary_pass_groups_all_groundings_per_atom() -> None:
    # both groundings of `any` update any(k) in the same pass: one row, 2 sources, cause the smaller one
    ev = run("""
    item(b)
    item(a)
    any(k):[0.5,1] <-0 item(X)
    """)
    (row,) = rows(ev, "any(k)")
    assert (row.cause_kind, row.grounding, row.n_sources) == (CAUSE_RULE, ("b",), 2)  # b is node 0


def test_pass_limit_boundary() -> None:
    chain = "a(x)\nb(X) <-0 a(X)\nc(X) <-0 b(X)\nd(X) <-0 c(X)\n"  # changes in passes 1..3, pass 4 quiet
    assert "d(x)" in interp(run(chain, max_passes=4))
    with pytest.raises(FixpointError):
        run(chain, max_passes=3)


# ---- immediate rules ---------------------------------------------------------------------------------

IMMEDIATE_FIRST_CLEARS = """
a(x)
free(x)
clear: free(X):[0,0] <-! a(X) {override}
go: go(X) <-! free(X)
"""
IMMEDIATE_FIRST_GOES = """
a(x)
free(x)
go: go(X) <-! free(X)
clear: free(X):[0,0] <-! a(X) {override}
"""


def test_immediate_rules_apply_one_at_a_time_in_rule_order() -> None:
    # `clear` first: free(x) is false before `go` is looked at again, so go(x) never fires
    ev = run(IMMEDIATE_FIRST_CLEARS)
    assert interp(ev) == {"a(x)": (1.0, 1.0), "free(x)": (0.0, 0.0)}
    # `go` first: it fires, then `clear`
    ev = run(IMMEDIATE_FIRST_GOES)
    assert interp(ev) == {"a(x)": (1.0, 1.0), "free(x)": (0.0, 0.0), "go(x)": (1.0, 1.0)}
    assert [(atom_text(c.atom), c.pass_no) for c in ev.changes if c.cause_kind == CAUSE_RULE] == [
        ("go(x)", 1), ("free(x)", 1)]


def test_same_rules_without_immediate_fire_together() -> None:
    ev = run(IMMEDIATE_FIRST_CLEARS.replace("<-!", "<-0"))
    assert interp(ev)["go(x)"] == (1.0, 1.0)  # both read pass 1's starting interpretation


def test_immediate_groundings_apply_smallest_first() -> None:
    # m is node 0, c node 1: got(m) takes the single token, then `take` clears it before got(c)
    ev = run("""
    want(m)
    want(c)
    free(k)
    take: free(K):[0,0] <-! got(X), free(K) {override}
    grab: got(X) <-! want(X), free(K)
    """)
    got = interp(ev)
    assert got["got(m)"] == (1.0, 1.0) and "got(c)" not in got and got["free(k)"] == (0.0, 0.0)
    assert [(atom_text(c.atom), c.grounding) for c in ev.changes if c.cause_kind == CAUSE_RULE] == [
        ("got(m)", ("m", "k")), ("free(k)", ("k", "m"))]  # rule.variables order: head first


def test_immediate_application_carries_the_next_pass_number() -> None:
    ev = run("""
    a(x)
    b(X) <-0 a(X)
    c(X) <-! b(X)
    """)
    assert [(atom_text(c.atom), c.pass_no) for c in ev.changes] == [("a(x)", 0), ("b(x)", 1), ("c(x)", 2)]


def test_immediate_limit_boundary() -> None:
    chain = "a(x)\nb(X) <-! a(X)\nc(X) <-! b(X)\nd(X) <-! c(X)\n"  # three applications
    assert "d(x)" in interp(run(chain, max_immediate=3))
    with pytest.raises(FixpointError):
        run(chain, max_immediate=2)


def test_immediate_rule_on_a_static_head_does_not_loop() -> None:
    # the head is static: the grounding never "would change" it, so the phase ends at once
    ev = run("""
    %mode override
    p(a):[0,0] static
    flip: p(X):[1,1] <-! p(X):[0,0]
    """, max_immediate=5)
    assert interp(ev) == {"p(a)": (0.0, 0.0)}


# ---- inconsistency -----------------------------------------------------------------------------------

CONFLICT = """
%inconsistency {policy}
p(a):[0.75,1] @0
p(a):[0.25,0.5] @1
p(a):[1,1] @2
"""


@pytest.mark.parametrize("policy, at1, at2", [
    ("reset_freeze", FULL, FULL),          # [0,1] and frozen: the t=2 fact is ignored
    ("keep_old", (0.75, 1.0), (1.0, 1.0)),
    ("take_new", (0.25, 0.5), (1.0, 1.0)),  # t=2 conflicts again: take_new takes [1,1]
    ("hull", (0.25, 1.0), (1.0, 1.0)),
])
def test_inconsistency_policies(policy: str, at1: tuple[float, float], at2: tuple[float, float]) -> None:
    ev = evaluator(CONFLICT.format(policy=policy))
    got = []
    for _ in range(3):
        ev.step()
        got.append(ev.bound(("p", ("a",))))
    assert got == [(0.75, 1.0), at1, at2]
    code = ["reset_freeze", "keep_old", "take_new", "hull"].index(policy)
    t1 = rows(ev, "p(a)", 1)
    if policy == "keep_old":
        assert t1 == []  # I(a) kept: no change, no row
    else:
        assert [(c.cause_kind, c.cause_id, c.grounding, c.n_sources) for c in t1] == [(CAUSE_POLICY, code, None, 1)]
    assert ev.is_static(("p", ("a",))) == (policy == "reset_freeze")


@pytest.mark.parametrize("first, second, expected", [("[0,0]", "[1,1]", (1.0, 1.0)), ("[1,1]", "[0,0]", (0.0, 0.0))])
def test_take_new_falls_back_to_the_last_source(first: str, second: str, expected: tuple[float, float]) -> None:
    # Mi = [0,0] ∩ [1,1] is empty, so Mo ∩ Mi is too: the μ of the last source in source order wins
    ev = run(f"%inconsistency take_new\np(a):{first}\np(a):{second}\n")
    (row,) = ev.changes
    assert (row.new, row.cause_kind, row.cause_id, row.n_sources) == (expected, CAUSE_POLICY, 2, 2)


def test_hull_spans_the_old_interval_and_every_source() -> None:
    ev = run("""
    %inconsistency hull
    p(a):[0.5,0.5] @0
    p(a):[0,0] @1
    p(a):[0.75,0.75] @1
    """, 2)
    assert ev.bound(("p", ("a",))) == (0.0, 0.75)


def test_reset_freeze_freezes_even_without_a_change() -> None:
    # two disjoint sources on a never-set atom: the result [0,1] equals I(a) (no row) but p(a) is frozen
    ev = run("""
    p(a):[0,0] @0
    p(a):[1,1] @0
    p(a):[1,1] @1
    """, 2)
    assert ev.changes == [] and ev.is_static(("p", ("a",)))


def test_policy_row_names_the_first_incoming_rule_grounding() -> None:
    ev = run("""
    %inconsistency take_new
    p(a)
    trig(b)
    trig(c)
    off: p(a):[0,0] <-0 trig(X)
    """)
    (row,) = rows(ev, "p(a)", 0)[1:]
    assert (row.new, row.cause_kind, row.cause_id) == ((0.0, 0.0), CAUSE_POLICY, 2)
    assert (row.grounding, row.grounding_rule, row.n_sources) == (("b",), 0, 2)


def test_abort_names_atom_time_and_both_sources() -> None:
    ev = evaluator("""
    %inconsistency abort
    p(a) @0
    trig(a) @1
    clear: p(X):[0,0] <-0 trig(X)
    """)
    ev.step()
    with pytest.raises(InconsistencyError) as err:
        ev.step()
    msg = str(err.value)
    fact_name = ev.facts[0].name
    assert "p(a)" in msg and "t=1" in msg
    assert fact_name in msg                       # the source of the old bound
    assert "clear" in msg and "X=a" in msg        # the incoming source, with its grounding


def test_abort_in_pass0_names_external_fact() -> None:
    ev = evaluator("%inconsistency abort\np(a)\n")
    ev.step()
    ev.add_fact("p", ("a",), 0.0, 0.0)
    with pytest.raises(InconsistencyError, match=r"p\(a\).*t=1.*fact.*external fact #0"):
        ev.step()


def test_consistent_updates_under_abort_do_not_raise() -> None:
    ev = run("%inconsistency abort\np(a):[0.5,1]\np(a):[0,0.75] @1\n", 2)
    assert interp(ev) == {"p(a)": (0.5, 0.75)}


# ---- fixpoint errors -----------------------------------------------------------------------------

def test_override_oscillation_raises_fixpoint_error() -> None:
    ev = evaluator("""
    %mode override
    p(a)
    q(a):[0,0]
    up: q(X):[1,1] <-0 p(X), q(X):[0,0]
    down: q(X):[0,0] <-0 p(X), q(X):[1,1]
    """, max_passes=10)
    with pytest.raises(FixpointError) as err:
        ev.step()
    assert "t=0" in str(err.value) and "q(a)" in str(err.value)


def test_take_new_oscillation_of_immediate_rules_raises_fixpoint_error() -> None:
    ev = evaluator("""
    %inconsistency take_new
    p(a)
    q(a):[0,0]
    on: q(X):[1,1] <-! p(X), q(X):[0,0]
    off: q(X):[0,0] <-! p(X), q(X):[1,1]
    """, max_immediate=50)
    with pytest.raises(FixpointError) as err:
        ev.step()
    assert "t=0" in str(err.value) and "q(a)" in str(err.value)
    assert len([c for c in ev.changes if c.cause_kind == CAUSE_POLICY]) == 50


# ---- sources, numbering, nodes ---------------------------------------------------------------------

def test_graph_facts_come_first_in_source_order_and_numbering() -> None:
    program = parse_program("p(a):[0,0.75] @0\nq(a)\n", "<test>")
    g = Fact("g0", Literal("p", (Term("a", False),), 0.25, 1.0))
    ev = ReferenceEvaluator(program, graph_nodes=["z"], graph_facts=[g])
    ev.step()
    assert ev.nodes == ["z", "a"]
    (row,) = rows(ev, "p(a)")
    assert (row.new, row.cause_kind, row.cause_id, row.n_sources) == ((0.25, 0.75), CAUSE_FACT, 0, 2)
    assert rows(ev, "q(a)")[0].cause_id == 2  # program facts are numbered after the graph's


def test_node_order_graph_then_program_then_graph_fact_extras_then_external() -> None:
    program = parse_program("q(b)\nq(a)\n", "<test>")
    g = Fact("g0", Literal("p", (Term("zz", False), Term("a", False))))
    ev = ReferenceEvaluator(program, graph_nodes=["y", "a"], graph_facts=[g])
    ev.add_fact("q", ("new",), 1.0, 1.0)
    assert ev.nodes == ["y", "a", "b", "zz", "new"]


def test_external_facts_are_numbered_in_order_and_add_nodes() -> None:
    ev = evaluator("a(x)\nb(X) <-0 a(X)\n")
    ev.add_fact("a", ("y",), 1.0, 1.0)
    ev.step()
    ev.add_fact("a", ("z",), 1.0, 1.0)
    ev.add_fact("a", ("y",), 0.5, 1.0)
    ev.step()
    assert ev.nodes == ["x", "y", "z"]
    assert [(atom_text(c.atom), c.t, c.cause_kind, c.cause_id) for c in ev.changes if c.cause_kind != CAUSE_RULE] == [
        ("a(x)", 0, CAUSE_FACT, 0), ("a(y)", 0, CAUSE_EXTERNAL, 0), ("a(z)", 1, CAUSE_EXTERNAL, 1)]
    assert interp(ev)["b(z)"] == (1.0, 1.0)


# ---- properties over random programs ---------------------------------------------------------------

def _run_scenario(sc: Scenario) -> ReferenceEvaluator:
    ev = ReferenceEvaluator(sc.program, sc.graph.nodes, sc.graph.facts, max_passes=40, max_immediate=200,
                            graph_edges=sc.graph_edges)
    for t in range(sc.steps):
        for f in sc.externals[t]:
            ev.add_fact(f.pred, f.args, f.lower, f.upper, f.static)
        try:
            ev.step()
        except FixpointError:
            break
    return ev


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_trace_replays_to_the_interpretation(sc: Scenario) -> None:
    """Every row's old bound is the atom's bound at that moment; replaying the rows rebuilds the state."""
    ev = _run_scenario(sc)
    state: dict = {}
    for c in ev.changes:
        assert state.get(c.atom, FULL) == c.old and c.old != c.new
        assert 0.0 <= c.new[0] <= c.new[1] <= 1.0
        state[c.atom] = c.new
    if ev.t == sc.steps:  # completed: no FixpointError left a step half done
        assert {a: iv for a, iv in state.items() if iv != FULL} == ev.interpretation()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenarios())
def test_intersection_keep_old_persistent_only_narrows(sc: Scenario) -> None:
    """With intersection everywhere, keep_old and persistent steps, knowledge only grows."""
    rules = [dataclasses.replace(r, mode=None) for r in sc.program.rules]
    program = dataclasses.replace(sc.program, rules=rules, mode="intersection", timesteps="persistent",
                                  inconsistency="keep_old")
    for c in _run_scenario(dataclasses.replace(sc, program=program)).changes:
        assert c.old[0] <= c.new[0] and c.new[1] <= c.old[1]
