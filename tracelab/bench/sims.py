"""The simulator workloads of `bench env`, `bench engine` and kernel_ab: war.toml's base game at a team size
(every agent on its base, the default map) through its spec (rules/gridworld/war.toml on DeclaredWorlds: the
engine, the read-back and the observations in one compiled call) and through RefSim (the hand-written oracle),
each stepped by a loop of fixed-seed random red actions (blue: the spec's rules, RefSim's scripted opponent)
that reads what an agent is given and restarts finished worlds; cpu_rates times such a loop."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from tracelab.bench.common import calibrate, summarize
from tracelab.envs.declared.gridwar import scenario_spec
from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds
from tracelab.envs.declared.recording import handover_due
from tracelab.game.refsim import RefSim
from tracelab.game.scenario import Scenario, builtin_scenario


def team_scenario(agents: int) -> Scenario:
    """war.toml's base game with `agents` a team on the default map, every agent on its base: what war.toml
    plays at every team size (its advanced game plays one agent a team, war.toml's [env.require])."""
    base = builtin_scenario("base")
    if agents == 1:
        return base
    return replace(base, name=f"base-{agents}v{agents}", agents_per_team=agents, red_starts=None,
                   blue_starts=None)


def team_spec(agents: int) -> WorldSpec:
    """war.toml loaded with the params of team_scenario(agents)."""
    path, params = scenario_spec(team_scenario(agents))
    return load_spec(path, **params)


class SpecLoop:
    """A batch of the spec's worlds stepped as the envs step them: fixed-seed random actions of every red
    agent (the spec's rules play blue), every agent's observation and reward read, finished worlds restarted,
    and (with `trace`) the change log taken at the tracer's cadence (recording.handover_due), so that a traced
    figure is what a traced run pays."""

    def __init__(self, worlds: DeclaredWorlds, trace: bool, seed: int = 0) -> None:
        self.worlds, self.trace = worlds, trace
        self.rng = np.random.default_rng(seed)
        self._steps_waiting = 0
        worlds.use_generators([np.random.default_rng(seed + i) for i in range(worlds.n_worlds)])
        worlds.engine.trace_on[:] = trace
        worlds.engine.take_trace()
        worlds.reset(np.arange(worlds.n_worlds))

    def run(self, steps: int) -> None:
        w = self.worlds
        red = self.rng.integers(0, w.n_actions, (steps, w.n_worlds, w.n_agents))
        for i in range(steps):
            w.step(red[i])
            for agent in range(w.n_agents):
                w.observations(agent)
                w.rewards(agent)
            done = w.terminated() | w.truncated(None)
            ended = bool(done.any())
            if self.trace:
                self._steps_waiting += 1
                if handover_due(w.engine, self._steps_waiting, ended):
                    self._steps_waiting = 0
                    w.engine.take_trace()
            if ended:
                w.reset(np.flatnonzero(done))


class RefLoop:
    """RefSim stepped as SpecLoop steps the spec: fixed-seed random red actions, the scripted blue
    opponent, finished worlds reset."""

    def __init__(self, sim: RefSim, seed: int = 0) -> None:
        self.sim = sim
        self.rng = np.random.default_rng(seed)
        self.ids = np.asarray(sim.scenario.action_ids, np.int64)
        self.shape = (sim.n_worlds, sim.scenario.agents_per_team)
        sim.reset(seed=seed)

    def run(self, steps: int) -> None:
        sim = self.sim
        red = self.rng.choice(self.ids, (steps, *self.shape))
        for i in range(steps):
            res = sim.step(red[i], sim.scripted_actions("blue"))
            done = res.terminated | res.truncated
            if done.any():
                sim.reset(worlds=done)


def cpu_rates(run: Callable[[int], Any], worlds: int, repeats: int, target_s: float) -> dict[str, Any]:
    """Env-steps per CPU second of run(k) (k steps of `worlds` worlds): a calibrated block, a warm-up, then
    `repeats` blocks timed by this process's CPU time (on this shared machine the wall clock also counts the
    turns of other processes, which differ from one block to the next)."""
    block = calibrate(run, target_s)
    run(block)
    rates_ = []
    for _ in range(max(1, repeats)):
        c0 = time.process_time()
        run(block)
        rates_.append(block * worlds / max(time.process_time() - c0, 1e-9))
    return summarize(rates_).to_dict()
