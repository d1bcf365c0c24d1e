"""What RuleSim's batched env (vector_env) and the GridWar trainer share: the simulator backend, the spaces,
the resets and a step (the action masks: tracelab/game/action_mask.py, RefSim's too)."""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from tracelab.envs.tracer import EpisodeTracer
from tracelab.game.action_mask import ActionMasker
from tracelab.game.refsim import RefSim
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import Scenario, builtin_scenario

BACKENDS = ("rules", "reference")
Simulator = RuleSim | RefSim


def resolve_scenario(scenario: Scenario | str) -> Scenario:
    """A Scenario, or the name of a built-in one (base, advanced, nonmarkov)."""
    return builtin_scenario(scenario) if isinstance(scenario, str) else scenario


def make_sim(scenario: Scenario, backend: str, n_worlds: int, stack_previous: bool, trace: bool,
             kernel: str = "auto") -> Simulator:
    """RuleSim ("rules", the engine; `trace` turns its change log on) or RefSim ("reference", no trace).
    `kernel`: the engine's (tracelab.engine.Engine); an env never waits for a compile, so "compiled" not
    yet cached is built in the background while the engine starts on the counting kernel."""
    if backend == "rules":
        return RuleSim(scenario, n_worlds, seed=None, stack_previous=stack_previous, trace=trace, kernel=kernel,
                       background_compile=True)
    if kernel != "auto":
        raise ValueError(f"kernel {kernel!r} is the rule engine's: it needs backend 'rules', not {backend!r}")
    if backend == "reference":
        return RefSim(scenario, n_worlds, seed=None, stack_previous=stack_previous)
    raise ValueError(f"unknown backend {backend!r}; expected one of {BACKENDS}")


def observation_space(scenario: Scenario, stack_previous: bool) -> spaces.Box:
    """One team's observation (docs/game.md, Observations): x in [-1, W-1], y in [-1, H-1] (-1: dead or
    no bullet), bullet counts in [0, N * ammo]."""
    n, w, h = scenario.agents_per_team, scenario.width, scenario.height
    low = [-1.0, -1.0] * (2 * n)
    high = [w - 1.0, h - 1.0] * (2 * n)
    if scenario.advanced:
        low += [0.0, -1.0, -1.0] * n
        high += [float(n * scenario.ammo), w - 1.0, h - 1.0] * n
    if stack_previous:
        low, high = low * 2, high * 2
    return spaces.Box(np.array(low, np.float32), np.array(high, np.float32), dtype=np.float32)


def learner_action_space(scenario: Scenario) -> spaces.Discrete | spaces.MultiDiscrete:
    """Indices into scenario.action_ids: Discrete for one agent, MultiDiscrete for a team."""
    n_act, n = scenario.n_actions, scenario.agents_per_team
    return spaces.Discrete(n_act) if n == 1 else spaces.MultiDiscrete([n_act] * n)


def reset_sim(sim: Any, tracer: EpisodeTracer | None, seed: int | None) -> np.ndarray:
    """An env's reset of every world: the simulator's observations [W, 2, D]; the tracer hands over the
    rows of the episodes cut short before, and begins the new episodes after."""
    if tracer is not None:
        tracer.before_reset()
    obs = sim.reset(seed=seed)
    if tracer is not None:
        tracer.begin(np.arange(sim.n_worlds), seed)
    return obs


def restart_worlds(sim: Any, tracer: EpisodeTracer | None, done: np.ndarray) -> np.ndarray:
    """The same-step autoreset: the worlds of the bool mask `done` begin new episodes now (the tracer
    numbers them in world order). Returns the simulator's observations [W, 2, D]."""
    obs = sim.reset(worlds=done)
    if tracer is not None:
        tracer.begin(np.flatnonzero(done), None)
    return obs


def step_learner(sim: Any, masker: ActionMasker, tracer: Any, action: Any, n_worlds: int,
                 space: Any) -> tuple[Any, np.ndarray]:
    """One step with red playing `action` (indices into the scenario's actions, [n_worlds, N] after
    reshaping) and blue playing the scripted policy; the step is handed to the tracer, if any.
    Returns the simulator's StepResult and blue's actions (spec ids, [n_worlds, N])."""
    idx = np.asarray(action, np.int64).reshape(n_worlds, -1)
    if ((idx < 0) | (idx >= masker.n_actions)).any():
        raise ValueError(f"action {action!r} is outside the action space {space}")
    red = masker.ids[idx]
    blue = sim.scripted_actions("blue")
    res = sim.step(red, blue)
    if tracer is not None:
        tracer.stepped(res, red, blue)
    return res, blue
