"""The rule game leaves an explainable trace: GridWar through its spec (rules/gridworld/war.toml, the base game's
default map, red on its base in the bottom-right corner, c7_7) names, in the engine's change log, the rule
that made a move unsafe, keeps the agent where it was (the shield), and shows a safe move as a leave and an
arrival. (RuleSim's trace tests, which put agents anywhere, went with it; the spec's agents start on their
bases.)"""
from __future__ import annotations

import numpy as np
import pytest

from tracelab.envs.declared.gridwar import WAR_SPEC
from tracelab.envs.declared.spec import load_spec
from tracelab.envs.declared.world import DeclaredWorld

RED, START, ABOVE = "red-agent-1", "c7_7", "c6_7"


def trace_rows(world: DeclaredWorld) -> list[dict]:
    """The engine's change rows since the last call, each with the atom's text and the cause's name."""
    e = world.engine
    tr = e.take_trace()
    return [{"atom": e.atom_text(int(tr["atom"][i])),
             "cause": e.cause_name(int(tr["cause_kind"][i]), int(tr["cause_id"][i])),
             "new": (float(tr["new_lower"][i]), float(tr["new_upper"][i]))}
            for i in range(len(tr["atom"]))]


@pytest.mark.parametrize(("action", "rule"), [("right", "u_right_edge"), ("down", "u_down_edge")])
def test_trace_explains_an_unsafe_move_and_the_shield(action: str, rule: str) -> None:
    spec = load_spec(WAR_SPEC)
    world = DeclaredWorld(spec, trace=True)
    rng = np.random.default_rng(0)
    world.reset(rng)
    assert world.engine.query(f"atLoc({RED},{START})") == (1.0, 1.0)
    trace_rows(world)
    world.step(spec.action_names.index(action), rng)  # off the map from the corner
    rows = trace_rows(world)
    unsafe = [x for x in rows if x["atom"] == f"unsafe({RED})"]
    assert len(unsafe) == 1 and unsafe[0]["cause"] == rule and unsafe[0]["new"] == (1.0, 1.0)
    # the shield: the agent's location atoms do not change in this step (no move, no dest either)
    assert not [x for x in rows if x["atom"].startswith((f"atLoc({RED},", f"dest({RED},"))]
    assert world.engine.query(f"atLoc({RED},{START})") == (1.0, 1.0)
    world.step(spec.action_names.index("up"), rng)  # a safe move afterwards: the agent leaves and arrives
    moved = {x["atom"]: (x["new"], x["cause"]) for x in trace_rows(world) if x["atom"].startswith(f"atLoc({RED},")}
    assert moved == {f"atLoc({RED},{START})": ((0.0, 0.0), "m_leave"),
                     f"atLoc({RED},{ABOVE})": ((1.0, 1.0), "m_go")}
