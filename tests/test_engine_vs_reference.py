"""The compiled Engine against the reference evaluator on random programs (tests/strategies.py).

After every step, for every world: the same interpretation, the same multiset of trace rows (t, pass,
atom, old, new, cause kind, cause id, grounding rule and values, n_sources), and immediate-rule rows in the
same order. Engine ids are mapped to names through eng.vocabulary() and eng.groundings; the reference
speaks names. Limits are small (MAX_PASSES, MAX_IMMEDIATE) so that oscillating programs stay cheap; both
evaluators must then raise FixpointError at the same step.
"""
from __future__ import annotations

import os
from collections import Counter
from collections.abc import Sequence

import numpy as np
from hypothesis import HealthCheck, given, settings
from strategies import ExtFact, Scenario, scenarios
from tracelab.engine import CAUSE_EXTERNAL, CAUSE_POLICY, CAUSE_RULE, Engine
from tracelab.engine.errors import FixpointError, InconsistencyError
from tracelab.engine.reference import ReferenceEvaluator, atom_text

MAX_PASSES = 40
MAX_IMMEDIATE = 200
WORLDS = 2
# TRACELAB_EXAMPLES scales the example counts for a longer hunt (the default keeps the file under 60 s)
SCALE = float(os.environ.get("TRACELAB_EXAMPLES", "1"))
SETTINGS = settings(max_examples=int(200 * SCALE), deadline=None, suppress_health_check=[HealthCheck.too_slow],
                    print_blob=True)

Row = tuple  # (t, pass_no, atom text, old, new, cause_kind, cause_id, grounding rule, grounding values, n_sources)


def reference_rows(ref: ReferenceEvaluator, start: int) -> list[Row]:
    return [(c.t, c.pass_no, atom_text(c.atom), c.old, c.new, c.cause_kind, c.cause_id, c.grounding_rule,
             c.grounding, c.n_sources) for c in ref.changes[start:]]


def engine_rows(eng: Engine, trace: dict[str, np.ndarray], world: int, ext_ids: dict[int, int] | None) -> list[Row]:
    """The world's rows, in trace order, with ids turned into names. ext_ids maps engine external-fact
    numbers to the numbers the world's reference gave the same facts (None: the same numbers)."""
    voc = eng.vocabulary()
    nodes, labels = voc["nodes"], voc["labels"]
    lab, arg0, arg1 = voc["atom_label"], voc["atom_arg0"], voc["atom_arg1"]
    table = eng.groundings
    out = []
    for i in np.flatnonzero(trace["world"] == world):
        a = int(trace["atom"][i])
        args = [nodes[arg0[a]]] + ([nodes[arg1[a]]] if arg1[a] >= 0 else [])
        text = f"{labels[lab[a]]}({','.join(args)})"
        g = int(trace["grounding"][i])
        if g >= 0:
            g_rule = int(table.rule[g])
            g_values = tuple(nodes[v] for v in table.var_values[table.var_ptr[g]:table.var_ptr[g + 1]])
        else:
            g_rule, g_values = None, None
        kind, cid = int(trace["cause_kind"][i]), int(trace["cause_id"][i])
        if kind == CAUSE_EXTERNAL and ext_ids is not None:
            cid = ext_ids[cid]
        out.append((int(trace["t"][i]), int(trace["pass_no"][i]), text,
                    (float(trace["old_lower"][i]), float(trace["old_upper"][i])),
                    (float(trace["new_lower"][i]), float(trace["new_upper"][i])),
                    kind, cid, g_rule, g_values, int(trace["n_sources"][i])))
    return out


def immediate_rows(rows: Sequence[Row], immediate: Sequence[bool]) -> list[Row]:
    """Rows made by immediate-rule applications (rule rows, and policy rows whose grounding is immediate):
    their order is part of the contract."""
    return [r for r in rows if r[1] >= 1 and r[5] in (CAUSE_RULE, CAUSE_POLICY) and r[7] is not None
            and immediate[r[7]]]


def check_step(eng: Engine, trace: dict[str, np.ndarray], world: int, ref: ReferenceEvaluator, start: int,
               ext_ids: dict[int, int] | None, sc: Scenario) -> None:
    want = {atom_text(a): iv for a, iv in ref.interpretation().items()}
    assert eng.interpretation(world) == want, f"interpretation, world {world}, t={ref.t - 1}"
    got_rows, want_rows = engine_rows(eng, trace, world, ext_ids), reference_rows(ref, start)
    missing = Counter(want_rows) - Counter(got_rows)
    extra = Counter(got_rows) - Counter(want_rows)
    assert not missing and not extra, (f"trace, world {world}, t={ref.t - 1}\n"
                                       f"only in reference: {sorted(missing, key=str)}\n"
                                       f"only in engine:    {sorted(extra, key=str)}")
    immediate = [r.immediate for r in sc.program.rules]
    assert immediate_rows(got_rows, immediate) == immediate_rows(want_rows, immediate), "immediate order"


def add_external(eng: Engine, ref: ReferenceEvaluator, f: ExtFact, world: int | None) -> None:
    eng.add_fact(eng.atom(f.pred, *f.args), f.lower, f.upper, world=world, static=f.static)
    ref.add_fact(f.pred, f.args, f.lower, f.upper, f.static)


def run_and_compare(sc: Scenario, kernel: str = "counting") -> None:
    per_world = bool(sc.world_externals)
    eng = Engine(sc.program, sc.graph, worlds=WORLDS, trace=True, max_passes=MAX_PASSES,
                 max_immediate=MAX_IMMEDIATE, kernel=kernel)
    assert eng.kernel == kernel
    # the same facts everywhere: one reference stands for every world
    refs = [ReferenceEvaluator(sc.program, sc.graph.nodes, sc.graph.facts, MAX_PASSES, MAX_IMMEDIATE,
                                  graph_edges=sc.graph_edges)
            for _ in range(WORLDS if per_world else 1)]
    # engine external facts are numbered over all worlds, each reference numbers its own world's
    ext_ids: dict[int, int] = {}  # engine number -> that world's reference number
    n_ref = [0] * len(refs)
    for t in range(sc.steps):
        if per_world:
            for w, ref in enumerate(refs):
                for f in sc.world_externals[w][t]:
                    ext_ids[len(ext_ids)] = n_ref[w]
                    n_ref[w] += 1
                    add_external(eng, ref, f, w)
        else:
            for f in sc.externals[t]:
                add_external(eng, refs[0], f, None)
        starts = [len(ref.changes) for ref in refs]
        ref_error = None
        for ref in refs:
            try:
                ref.step()
            except FixpointError as e:
                ref_error = e
        if ref_error is not None:
            try:
                eng.step()
            except FixpointError:
                return
            raise AssertionError(f"the reference raised at t={t} ({ref_error}) but the engine did not")
        eng.step()
        trace = eng.take_trace()
        for w in range(WORLDS):
            ref = refs[w] if per_world else refs[0]
            check_step(eng, trace, w, ref, starts[w] if per_world else starts[0],
                       ext_ids if per_world else None, sc)
    assert eng.t == sc.steps


@SETTINGS
@given(scenarios())
def test_same_external_facts_in_every_world(sc: Scenario) -> None:
    run_and_compare(sc)


@SETTINGS
@given(scenarios(per_world=WORLDS))
def test_different_external_facts_per_world(sc: Scenario) -> None:
    run_and_compare(sc)


@settings(max_examples=int(100 * SCALE), deadline=None, suppress_health_check=[HealthCheck.too_slow],
          print_blob=True)
@given(scenarios(policies=("abort",)))
def test_abort_stops_both_at_the_same_step(sc: Scenario) -> None:
    """Under abort both raise InconsistencyError at the same step, and agree on every step before it."""
    run_until_abort(sc, "counting")


def run_until_abort(sc: Scenario, kernel: str) -> None:
    eng = Engine(sc.program, sc.graph, worlds=WORLDS, trace=True, max_passes=MAX_PASSES,
                 max_immediate=MAX_IMMEDIATE, kernel=kernel)
    ref = ReferenceEvaluator(sc.program, sc.graph.nodes, sc.graph.facts, MAX_PASSES, MAX_IMMEDIATE,
                                  graph_edges=sc.graph_edges)
    for t in range(sc.steps):
        for f in sc.externals[t]:
            add_external(eng, ref, f, None)
        start = len(ref.changes)
        try:
            ref.step()
        except (InconsistencyError, FixpointError) as e:
            try:
                eng.step()
            except type(e):
                return
            raise AssertionError(f"the reference raised {e!r} at t={t} but the engine did not") from e
        eng.step()
        trace = eng.take_trace()
        for w in range(WORLDS):
            check_step(eng, trace, w, ref, start, None, sc)


# ---- the lanes kernel (crisp programs: heads, facts and external facts set [0,0], [1,1] or [0,1]) ----
@SETTINGS
@given(scenarios(crisp=True))
def test_lanes_kernel_same_external_facts_in_every_world(sc: Scenario) -> None:
    run_and_compare(sc, kernel="lanes")


@SETTINGS
@given(scenarios(per_world=WORLDS, crisp=True))
def test_lanes_kernel_different_external_facts_per_world(sc: Scenario) -> None:
    run_and_compare(sc, kernel="lanes")


@settings(max_examples=int(100 * SCALE), deadline=None, suppress_health_check=[HealthCheck.too_slow],
          print_blob=True)
@given(scenarios(policies=("abort",), crisp=True))
def test_lanes_kernel_aborts_at_the_same_step(sc: Scenario) -> None:
    run_until_abort(sc, "lanes")
