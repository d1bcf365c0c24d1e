"""Quantified body clauses and annotation functions (docs/language.md, "Quantifiers", "Annotation
functions"): random programs compared between the counting kernel and the reference evaluator, and
hand-written cases of each comparison, total / available, forall, each built-in function, user functions
(plain Python and numba) and the parser's located errors."""
from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from located import assert_located
from strategies import Scenario, scenarios
from test_engine_vs_reference import SCALE, run_and_compare, run_until_abort
from tracelab.engine import Engine, ProgramError, parse_program, register_annotation
from tracelab.engine import kernel as K
from tracelab.engine.annotations import unregister_annotation
from tracelab.engine.reference import ReferenceEvaluator, atom_text

AGG_SETTINGS = settings(max_examples=int(150 * SCALE), deadline=None,
                        suppress_health_check=[HealthCheck.too_slow], print_blob=True)


@AGG_SETTINGS
@given(scenarios(aggregates=True))
def test_random_aggregated_programs_agree_with_the_reference(sc: Scenario) -> None:
    run_and_compare(sc)


@AGG_SETTINGS
@given(scenarios(per_world=2, aggregates=True))
def test_random_aggregated_programs_per_world_facts(sc: Scenario) -> None:
    run_and_compare(sc)


@settings(max_examples=int(60 * SCALE), deadline=None, suppress_health_check=[HealthCheck.too_slow],
          print_blob=True)
@given(scenarios(policies=("abort",), aggregates=True))
def test_random_aggregated_programs_abort_at_the_same_step(sc: Scenario) -> None:
    run_until_abort(sc, "counting")


# ---- hand-written semantics -------------------------------------------------------------------------

# x has four friends: f1..f3 popular ([1,1]), f4 explicitly not ([0,0]); y has two friends: f1 popular and
# f5 never set ([0,1]); z has no friend.
FRIENDS = """
friend(x,f1)
friend(x,f2)
friend(x,f3)
friend(x,f4)
friend(y,f1)
friend(y,f5)
person(z)
popular(f1)
popular(f2)
popular(f3)
popular(f4):[0,0]
"""


def run_both(text: str, steps: int = 1, **engine_kw) -> tuple[dict[str, tuple[float, float]], Engine]:
    """The final interpretation of both evaluators (they must agree) and the engine."""
    program = parse_program(text)
    eng = Engine(program, **engine_kw)
    ref = ReferenceEvaluator(program)
    for _ in range(steps):
        eng.step()
        ref.step()
    want = {atom_text(a): iv for a, iv in ref.interpretation().items()}
    assert eng.interpretation(0) == want
    return want, eng


def fired(text: str, quantifier: str) -> set[str]:
    interp, _ = run_both(FRIENDS + f"liked(X) <-0 friend(X,Y), {quantifier} popular(Y)\n")
    return {a[len("liked("):-1] for a in interp if a.startswith("liked(")}


@pytest.mark.parametrize("quantifier, expected", [
    ("[>= 3]", {"x"}), ("[> 3]", set()), ("[<= 1]", {"y"}), ("[< 1]", set()), ("[== 1]", {"y"}),
    ("[>= 75%]", {"x"}), ("[> 75%]", set()), ("[>= 50%]", {"x", "y"}), ("[< 60%]", {"y"}),
    ("[== 50%]", {"y"}), ("[<= 0]", set()), ("[forall]", set()),
    # available: y's f5 is never set, so it is no candidate: 1 of 1
    ("[== 100% available]", {"y"}), ("[forall available]", {"y"}), ("[>= 75% total]", {"x"}),
    ("[== 1 available]", {"y"}),
])
def test_comparisons_counts_percentages_total_and_available(quantifier: str, expected: set[str]) -> None:
    assert fired(FRIENDS, quantifier) == expected


def test_available_counts_a_clause_that_holds_of_unset_atoms_only_when_set() -> None:
    # `popular(Y):[0,1]` holds of every atom; `available` counts only the set ones: x 4, y 1
    text = FRIENDS + "n3(X) <-0 friend(X,Y), [>= 3 available] popular(Y):[0,1]\n" \
                     "n2(X) <-0 friend(X,Y), [== 2] popular(Y):[0,1]\n"
    interp, _ = run_both(text)
    assert "n3(x)" in interp and "n3(y)" not in interp
    assert "n2(y)" in interp and "n2(x)" not in interp


def test_forall_and_a_head_without_candidates() -> None:
    interp, _ = run_both(FRIENDS.replace("popular(f4):[0,0]", "popular(f4)") +
                         "all(X) <-0 friend(X,Y), [forall] popular(Y)\nnone(X) <-0 person(X), friend(X,Y), "
                         "[== 0] popular(Y)\n")
    assert "all(x)" in interp and "all(y)" not in interp  # y's f5 is [0,1]: not popular
    assert not any(a.startswith("none(") for a in interp)  # z has no join: no head grounding


def test_the_pyreason_threshold_example_is_evaluated_per_head() -> None:
    """PyReason's doc example (popular if at least half of one's friends are): PyReason counts the
    candidates of all heads together; here a head counts its own friends only."""
    text = """
    friend(a,b)
    friend(a,c)
    friend(d,b)
    friend(d,e)
    friend(d,f)
    friend(d,g)
    popular(b)
    popular(e)
    popular(X) <-1 friend(X,Y), [>= 50%] popular(Y)
    """
    interp, _ = run_both(text, steps=2)
    assert interp["popular(a)"] == (1.0, 1.0)  # b of b, c: 50%
    assert interp["popular(d)"] == (1.0, 1.0)  # b, e of four: 50%
    assert "popular(c)" not in interp


RISK = """
exposed(x,a)
exposed(x,b)
exposed(x,c)
risk(a):[0.5,0.75]
risk(b):[0.25,0.25]
risk(c):[1,1]
"""


@pytest.mark.parametrize("function, options, expected", [
    ("average", "{weights=0,1}", (4.75 / 6, 5.0 / 6)),  # ignores weights: three exposed [1,1] and a, b, c
    ("weighted_average", "{weights=0,1}", (1.75 / 3, 2.0 / 3)),
    ("weighted_average", "{weights=1,1}", (4.75 / 6, 5.0 / 6)),
    ("weighted_average", "{weights=0,0}", None),  # the weights sum to 0: no firing
    ("min", "", (0.25, 0.25)),
    ("max", "", (1.0, 1.0)),
    ("average_lower", "", (4.75 / 6, 1.0)),
])
def test_builtin_annotation_functions(function: str, options: str, expected: tuple[float, float] | None) -> None:
    interp, _ = run_both(RISK + f"risk(X):{function} <-0 exposed(X,Y), risk(Y):[0,1] {options}\n")
    assert interp.get("risk(x)") == expected


def test_a_negated_head_sets_the_complement_of_the_function() -> None:
    interp, _ = run_both(RISK + "~safe(X):max <-0 exposed(X,Y), risk(Y):[0,1] {weights=0,1}\n")
    assert interp["safe(x)"] == (0.0, 0.0)


def test_quantifier_and_function_together_feed_only_atoms_that_hold() -> None:
    # risk(Y):[0.5,1] holds of a and c: 2 of 3 (>= 50%); min over exposed atoms and a, c
    interp, _ = run_both(RISK + "alarm(X):min <-0 exposed(X,Y), [>= 50%] risk(Y):[0.5,1]\n")
    assert interp["alarm(x)"] == (0.5, 0.75)


def test_the_firing_names_its_first_active_join() -> None:
    _, eng = run_both(FRIENDS + "liked(X) <-1 friend(X,Y), [>= 50%] popular(Y)\n", steps=2)
    trace = eng.take_trace()
    liked = [i for i in range(len(trace["atom"])) if eng.atom_text(int(trace["atom"][i])).startswith("liked(")]
    texts = sorted(eng.grounding_text(int(trace["grounding"][i])) for i in liked)
    assert texts == ["X=x, Y=f1", "X=y, Y=f1"]
    assert all(trace["cause_kind"][i] == K.CAUSE_RULE for i in liked)


# ---- user functions ---------------------------------------------------------------------------------

def spread(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float]:
    return float(lower.min()), float(upper.max())


@numba.njit
def half_max(lower, upper, weights):
    return 0.5 * lower.max(), 0.5 * upper.max()


@pytest.fixture
def user_functions():
    seconds = [register_annotation("spread", spread), register_annotation("half_max", half_max)]
    yield seconds
    unregister_annotation("spread")
    unregister_annotation("half_max")


def test_user_functions_in_passes_and_delayed_rules_without_recompiling(user_functions) -> None:
    assert all(s >= 0.0 for s in user_functions)  # seconds taken (measured by the bench, not asserted)
    text = RISK + """
    r1(X):spread <-0 exposed(X,Y), risk(Y):[0,1] {weights=0,1}
    r2(X):half_max <-2 exposed(X,Y), risk(Y):[0,1]
    r3(X):[1,1] <-0 r1(X):[0.25,1]
    """
    program = parse_program(text)
    before = len(K.step_worlds.signatures)
    eng = Engine(program, worlds=3, trace_rows_per_step=1)  # tiny trace room: pauses of both kinds
    ref = ReferenceEvaluator(program)
    for _ in range(3):
        eng.step()
        ref.step()
        want = {atom_text(a): iv for a, iv in ref.interpretation().items()}
        for w in range(3):
            assert eng.interpretation(w) == want
    assert want["r1(x)"] == (0.25, 1.0) and want["r3(x)"] == (1.0, 1.0) and want["r2(x)"] == (0.5, 0.5)
    assert len(K.step_worlds.signatures) == before or before == 0  # no new kernel specialisation


def test_snapshots_keep_the_bounds_of_scheduled_function_firings() -> None:
    program = parse_program(RISK + "r(X):average_lower <-2 exposed(X,Y), risk(Y):[0,1] {weights=0,1}\n")
    eng = Engine(program, worlds=2)
    eng.step()
    snap = eng.snapshot()
    eng.run(2)
    assert eng.bound(eng.atom("r", "x"), 1) == (4.75 / 6, 1.0)  # average_lower ignores weights
    eng.restore(snap, np.array([1]))
    assert eng.bound(eng.atom("r", "x"), 1) == (0.0, 1.0)
    eng.run(1)  # the restored world replays step 1; the firing scheduled at t = 0 for t = 2 comes next
    assert eng.bound(eng.atom("r", "x"), 1) == (0.0, 1.0)
    eng.run(1)
    assert eng.bound(eng.atom("r", "x"), 1) == (4.75 / 6, 1.0)


def test_a_user_function_with_a_bad_bound_is_an_error_naming_it() -> None:
    register_annotation("broken", lambda lo, up, w: (0.9, 0.1))
    try:
        eng = Engine(parse_program(RISK + "r(X):broken <-0 exposed(X,Y)\n"))
        with pytest.raises(ValueError, match="'broken' .*rule rule8.*0.9"):
            eng.step()
    finally:
        unregister_annotation("broken")


def test_registering_a_builtin_name_or_a_bad_name_is_refused() -> None:
    with pytest.raises(ValueError, match="built-in"):
        register_annotation("average", spread)
    with pytest.raises(ValueError, match="lower-case"):
        register_annotation("Bad", spread)


def test_the_lanes_kernel_refuses_aggregated_rules_and_auto_takes_counting() -> None:
    program = parse_program(FRIENDS + "liked(X) <-1 friend(X,Y), [>= 50%] popular(Y)\n")
    with pytest.raises(ValueError, match=r"kernel='lanes' cannot run rule rule13 \(<string>:13:1\)"):
        Engine(program, worlds=64, kernel="lanes")
    assert Engine(program, worlds=64).kernel == "counting"


# ---- located errors ---------------------------------------------------------------------------------

@pytest.mark.parametrize("line, col, message", [
    ("h(X) <-0 a(X,Y), [>= x] b(Y)", 22, "expected a count (an integer) or a percentage"),
    ("h(X) <-0 a(X,Y), [>= 1.5] b(Y)", 22, "a count is an integer, found 1.5"),
    ("h(X) <-0 a(X,Y), [>= 150%] b(Y)", 22, "a percentage is at most 100%"),
    ("h(X) <-0 a(X,Y), [most] b(Y)", 19, "expected a quantifier after '['"),
    ("h(X) <-0 a(X,Y), [>= 1 some] b(Y)", 24, "expected ']' to close the quantifier"),
    ("h(X) <-0 a(X), [>= 1] b(Y)", 25, ("a variable of a quantified clause must occur in the head or in an "
                                        "unquantified binding clause")),
    ("h(X):median <-0 a(X)", 6, "unknown annotation function 'median'"),
    ("h(a):average", 6, "an annotation function names how a rule head's bound is computed"),
    ("h(X):average <-0 a(X) {weights=1,2}", 1, "gives 2 weights for 1 body clauses"),
    ("h(X) <-0 a(X) {weights=1}", 1, "gives weights but its head names no annotation function"),
    ("h(X):min <-! a(X)", 1, "is immediate"),
    ("h(X) <-0 a(X), [>= 50%] a(X) {weights=-1}", 39, "a weight is a number >= 0"),
])
def test_bad_quantifiers_and_functions_are_located_errors(line: str, col: int, message: str) -> None:
    with pytest.raises(ProgramError) as info:
        parse_program("a(b)\n" + line + "\n", "f.rules")
    assert_located(info.value, "f.rules", 2, col, message)


def test_an_engine_refuses_a_function_unregistered_since_parsing() -> None:
    register_annotation("gone", spread)
    program = parse_program(RISK + "r(X):gone <-0 exposed(X,Y)\n")
    unregister_annotation("gone")
    with pytest.raises(ProgramError, match="unknown annotation function 'gone'"):
        Engine(program)


def test_the_example_program() -> None:
    from tracelab.engine import load_program

    from tracelab import RULES_DIR
    program = load_program(RULES_DIR / "examples" / "popular.rules")
    eng, ref = Engine(program), ReferenceEvaluator(program)
    for _ in range(3):
        eng.step()
        ref.step()
    want = {atom_text(a): iv for a, iv in ref.interpretation().items()}
    assert eng.interpretation(0) == want
    assert want["popular(ann)"] == want["popular(dan)"] == want["star(ann)"] == (1.0, 1.0)
    assert want["influence(dan)"] == ((0.8 + 0.6) / 4, (1 + 0.6 + 1 + 1) / 4)


def test_an_engine_refuses_an_immediate_aggregated_rule_built_in_code() -> None:
    import dataclasses
    program = parse_program(RISK + "r(X):average <-0 exposed(X,Y)\n")
    program.rules[0] = dataclasses.replace(program.rules[0], immediate=True)
    with pytest.raises(ProgramError, match="is immediate"):
        Engine(program)


def test_every_builtin_has_a_kernel_code() -> None:
    from tracelab.engine.aggregate_tables import BUILTIN_CODES
    from tracelab.engine.annotations import BUILTINS
    assert set(BUILTIN_CODES) == set(BUILTINS)
    assert len(set(BUILTIN_CODES.values()) | {K.FN_FIXED, K.FN_USER}) == len(BUILTINS) + 2


def test_the_firing_prefers_a_join_whose_quantified_clause_holds() -> None:
    # k's first join (Y=u1, the smaller node id) has popular(u1) unset; the firing is named by Y=u2
    _, eng = run_both("friend(k,u1)\nfriend(k,u2)\npopular(u2)\n"
                      "liked(X) <-1 friend(X,Y), [>= 50%] popular(Y)\n", steps=2)
    trace = eng.take_trace()
    rows = [i for i in range(len(trace["atom"])) if eng.atom_text(int(trace["atom"][i])) == "liked(k)"]
    assert [eng.grounding_text(int(trace["grounding"][i])) for i in rows] == ["X=k, Y=u2"]


def test_why_explains_a_quantified_firing_from_the_store(tmp_path) -> None:
    from tracelab.engine import load_program

    from tracelab import RULES_DIR
    from tracelab.store.reader import open_run
    from tracelab.store.why import explain
    from tracelab.store.writer import TraceWriter
    eng = Engine(load_program(RULES_DIR / "examples" / "popular.rules"))
    meta = {"command": "pytest aggregates", "scenario": "popular", "rule_files": [], "seed": 0, "config": {}}
    with TraceWriter(tmp_path / "run", meta) as w:
        w.write_engine_program(eng)
        w.begin_episode(0, world=0, t_start=0, seed=0)
        for _ in range(3):
            eng.step()
            w.write_engine(np.array([0]), eng)
        w.end_episode(0, steps=3, outcome="draw", reward=0.0, rewards={}, t_end=2)
    tree = explain(open_run(tmp_path / "run"), 0, "popular(dan)", at=2)
    assert (tree.cause.kind, tree.cause.name, tree.cause.bindings) == ("rule", "popular", {"X": "dan", "Y": "bob"})
    assert [c.atom for c in tree.children] == ["friend(dan,bob)", "popular(bob)"]
    assert all(c.holds for c in tree.children)
