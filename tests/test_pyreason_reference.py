"""A small PyReason program reasons on the reference evaluator (tracelab/pyreason/reference_engine.py), not
the compiled engine, unless `pr.settings.tracelab_evaluator` says otherwise: both give the same rule trace
(the CSV files, Fixed-Point-Operation included), the same interpretation and the same counts, on programs
that use what PyReason's examples use (delays, passes, conflicts, the inconsistent predicate list, static
facts and rules, thresholds, inferred edges, closed-world predicates, persistence, reason(again=True))."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

import tracelab.pyreason as pr
from tracelab.errors import UserError

nx = pytest.importorskip("networkx")
pytest.importorskip("pandas")

from test_pyreason_trace_rows import cybersecurity_example, inconsistency_example  # noqa: E402

FRIENDS = Path(__file__).resolve().parent / "data" / "pyreason" / "friends_graph.graphml"


def forget() -> None:
    pr.reset()
    pr.reset_rules()
    pr.reset_settings()
    pr.api._program.ipl.clear()


@pytest.fixture(autouse=True)
def fresh() -> None:
    forget()


def hello_world() -> pr.Interpretation:
    pr.load_graphml(FRIENDS)
    pr.add_rule(pr.Rule("popular(x) <-1 popular(y), Friends(x,y), owns(y,z), owns(x,z)", "popular_rule"))
    pr.add_fact(pr.Fact("popular(Mary)", "popular_fact", 0, 2))
    return pr.reason(timesteps=2)


def chain(persistent: bool) -> Callable[[], pr.Interpretation]:
    """Several passes in a step (an immediate chain), a delayed rule, facts that end."""
    def program() -> pr.Interpretation:
        g = nx.DiGraph()
        nx.add_path(g, ["a", "b", "c", "d", "e"], link=1)
        pr.settings.persistent = persistent
        pr.load_graph(g)
        pr.add_rule(pr.Rule("reach(y) <- reach(x), link(x,y)", "reach_rule"))
        pr.add_rule(pr.Rule("seen(x):[0.4,0.9] <-2 reach(x)", "seen_rule"))
        pr.add_fact(pr.Fact("reach(a)", "start", 0, 1))
        pr.add_fact(pr.Fact("reach(c):[0.5,1]", "half", 2, 3))
        return pr.reason(timesteps=4)
    return program


def conflicts_and_statics() -> pr.Interpretation:
    g = nx.DiGraph()
    g.add_edge("a", "b", link=1)
    pr.load_graph(g)
    pr.add_inconsistent_predicate("sick", "healthy")
    pr.add_rule(pr.Rule("sick(x):[0.8,1] <- p(x)", "static_rule", set_static=True))
    pr.add_rule(pr.Rule("sick(y):[0.5,0.7] <- sick(x):[0.5,1], link(x,y)", "spread_rule"))
    pr.add_fact(pr.Fact("p(a)", "f_p", 0, 0))
    pr.add_fact(pr.Fact("healthy(a):[0.9,1]", "f_h", 2, 2))
    pr.add_fact(pr.Fact("healthy(b):[0.9,1]", "f_hb", 0, 3))
    pr.add_fact(pr.Fact("q(b):[0.2,0.6]", "q1", 1, 2))
    pr.add_fact(pr.Fact("q(b):[0.5,1]", "q2", 1, 1))
    pr.add_fact(pr.Fact("q(b):[0,0.1]", "q3", 2, 2))
    pr.add_fact(pr.Fact("r(a):[0.3,0.4]", "r_static", 0, 0, static=True))
    return pr.reason(timesteps=3)


def thresholds_edges_closed() -> pr.Interpretation:
    g = nx.DiGraph()
    for a, b in (("a", "b"), ("c", "b"), ("d", "b"), ("a", "c")):
        g.add_edge(a, b, knows=1)
    pr.load_graph(g)
    pr.add_closed_world_predicate("banned")
    pr.add_rule(pr.Rule("liked(y) <- knows(x,y), fan(x)", "liked_rule",
                        custom_thresholds=[pr.Threshold("greater_equal", ("number", "total"), 1),
                                           pr.Threshold("greater_equal", ("number", "total"), 2)]))
    pr.add_rule(pr.Rule("friend(x,y) <- fan(x), liked(y)", "friend_rule", infer_edges=True))
    pr.add_rule(pr.Rule("ok(x) <- fan(x), ~banned(x)", "ok_rule"))
    for n in ("a", "c", "d"):
        pr.add_fact(pr.Fact(f"fan({n})", f"fan_{n}", 0, 2))
    pr.add_fact(pr.Fact("banned(d)", "ban_d", 0, 2))
    return pr.reason(timesteps=2)


def again_with_facts_and_rules() -> pr.Interpretation:
    hello_world()
    pr.add_fact(pr.Fact("popular(Justin)", "justin_fact", 0, 1))
    pr.reason(timesteps=2, again=True)
    pr.add_rule(pr.Rule("famous(x) <- popular(x)", "famous_rule"))
    return pr.reason(timesteps=1, again=True)


def until_converged() -> pr.Interpretation:
    pr.load_graphml(FRIENDS)
    pr.add_rule(pr.Rule("popular(x) <-1 popular(y), Friends(x,y)", "popular_rule"))
    pr.add_fact(pr.Fact("popular(Mary)", "popular_fact", 0, 0))
    return pr.reason()


PROGRAMS = {"hello world": hello_world, "chain": chain(False), "chain, persistent": chain(True),
            "conflicts and statics": conflicts_and_statics, "thresholds, edges, closed": thresholds_edges_closed,
            "again": again_with_facts_and_rules, "until converged": until_converged,
            "PyReason's inconsistency example": inconsistency_example,
            "PyReason's cybersecurity example": cybersecurity_example}


def reasoned(program: Callable[[], pr.Interpretation], evaluator: str, folder: Path) -> dict[str, object]:
    forget()
    pr.settings.tracelab_evaluator = evaluator
    interpretation = program()
    pr.save_rule_trace(interpretation, str(folder))
    files = {p.name.split("_")[2]: p.read_text(encoding="utf-8") for p in folder.glob("rule_trace_*.csv")}
    return {"trace": files, "dict": interpretation.get_dict(), "time": interpretation.time,
            "fp_cnt": interpretation.fp_cnt, "kernel": interpretation.engine.kernel}


@pytest.mark.parametrize("name", PROGRAMS)
def test_the_reference_evaluator_reasons_as_the_compiled_engine(name: str, tmp_path: Path) -> None:
    compiled = reasoned(PROGRAMS[name], "compiled", tmp_path / "compiled")
    reference = reasoned(PROGRAMS[name], "reference", tmp_path / "reference")
    compiled_kernel = compiled.pop("kernel")
    assert compiled_kernel != "reference"
    # "again" ends with rules added: that reasoning goes on in a new compiled engine (api.continued_with)
    assert reference.pop("kernel") == (compiled_kernel if name == "again" else "reference")
    assert reference == compiled
    assert compiled["trace"]["nodes"].count("\n") > 1  # each program wrote rows


def test_auto_takes_the_reference_evaluator_for_a_small_program_only() -> None:
    assert hello_world().engine.kernel == "reference"
    forget()
    g = nx.DiGraph()
    nx.add_path(g, [f"n{k}" for k in range(60)], link=1)
    pr.load_graph(g)  # 60 nodes ** 3 variables * 3 steps: too many assignments for plain Python
    pr.add_rule(pr.Rule("popular(x) <-1 popular(y), link(y,x), link(x,z)", "popular_rule"))
    pr.add_fact(pr.Fact("popular(n0)", "popular_fact", 0, 0))
    assert pr.reason(timesteps=2).engine.kernel != "reference"


def test_the_evaluator_setting_is_checked() -> None:
    with pytest.raises(ValueError, match="tracelab_evaluator: one of auto, compiled, reference, got 'fast'"):
        pr.settings.tracelab_evaluator = "fast"


def test_a_recorded_reasoning_is_not_asked_of_the_reference_evaluator(tmp_path: Path) -> None:
    pr.settings.tracelab_evaluator = "reference"
    pr.settings.tracelab_run = str(tmp_path / "run")
    with pytest.raises(UserError, match="a recorded reasoning runs on the compiled engine"):
        hello_world()
    assert not (tmp_path / "run").exists()
