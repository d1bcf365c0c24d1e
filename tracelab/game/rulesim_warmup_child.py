"""The second process of a first run's compile (tracelab/game/rulesim_warmup.py): it builds the RuleSim
the first process builds, but never steps its engine, and calls every game kernel once, so that they
compile into numba's disk cache while the first process compiles the engine's step kernel.

    python -m tracelab.game.rulesim_warmup_child   (the RuleSim's arguments as JSON on stdin)
"""
from __future__ import annotations

import json
import sys
import tomllib
from typing import Any

import numpy as np

from tracelab.game.rulesim import RuleSim
from tracelab.game.rulesim_kernel import read_and_settle
from tracelab.game.scenario import Scenario, scenario_from_dict


def from_parent(message: bytes) -> dict[str, Any]:
    """compile_game_kernels' arguments from to_child's message."""
    args = json.loads(message)
    args["scenario"] = scenario_from_dict(tomllib.loads(args["scenario"]))
    return args


def compile_game_kernels(scenario: Scenario, n_worlds: int, stack_previous: bool, kernel: str, fused: bool) -> None:
    """Call every game kernel once, as a RuleSim of these arguments does, without stepping its engine."""
    class UnsteppedRuleSim(RuleSim):
        def _first_step(self, fused: bool) -> None:
            """The engine's step kernel is the other process's share."""

    sim = UnsteppedRuleSim(scenario, n_worlds, stack_previous=stack_previous, kernel=kernel, fused=fused)
    sim.scripted_actions("blue")
    actions = np.full((n_worlds, scenario.agents_per_team), scenario.action_ids[0], np.int64)
    sim._action_rows(actions, actions)
    read_and_settle(sim.engine.is_true(sim._read_atoms), *sim._settle_args)
    sim.engine.restore(sim._start, np.zeros(1, np.int64))
    if fused and sim.engine.fused_binding() is not None:
        sim._bind()
    # the envs' tracer's kernels, which a traced play calls next (deferred: envs sits above game; only this
    # process's entry point reaches up to it)
    from tracelab.envs.step_log import compile_for
    compile_for(sim)


def main() -> int:
    compile_game_kernels(**from_parent(sys.stdin.buffer.read()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
