"""`DeclaredParallelEnv`: a world declared by a spec with several agents (docs/worlds.md) as a PettingZoo
ParallelEnv.

- Agents are the spec's `[agents] names`, in order; each acts with Discrete(number of actions) and an
  agent left out of the actions dict does nothing (none of its facts is set for the step).
- Each agent's observation reads the spec's parts with `Agent` standing for it (the same space for all,
  gym_env.observation_space); its reward is the reward table and scaled atom with `Agent` = it.
- The episode ends for every agent at once: terminated when a `terminated` atom holds (any agent's),
  truncated at the step limit or a `truncated` atom; `agents` is then empty until reset.
- infos[agent]: `action_mask` (int8) when the spec declares a mask, and `t`.
- Randomness: `reset(seed=s)` seeds the env's own numpy Generator, drawn as DeclaredEnv draws."""
from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from tracelab.envs.declared.gym_env import RENDER_MODES, observation_space, painter_for, render_world
from tracelab.envs.declared.history import ObservationHistory
from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.envs.declared.world import DeclaredWorld


class DeclaredParallelEnv(ParallelEnv[str, Any, int]):
    metadata = {"name": "tracelab_declared_v0", "render_modes": RENDER_MODES, "render_fps": 4,
                "is_parallelizable": True}

    def __init__(self, spec: WorldSpec | str | os.PathLike[str], *, render_mode: str | None = None,
                 kernel: str = "auto", **params: Any) -> None:
        self.world_spec = spec if isinstance(spec, WorldSpec) else load_spec(spec, **params)
        self._painter = painter_for(self.world_spec, render_mode)
        self.render_mode = render_mode
        self.world = DeclaredWorld(self.world_spec, kernel=kernel)
        self.metadata = {**self.metadata, "render_fps": self.world_spec.render_fps}
        self.possible_agents = list(self.world_spec.agents)
        self.agents: list[str] = []
        self._obs_space = observation_space(self.world_spec)
        self._act_space = spaces.Discrete(len(self.world_spec.action_names))
        self._histories = [ObservationHistory(self.world_spec.previous) for _ in self.possible_agents]
        self._np_random, _ = seeding.np_random(None)
        self._last: np.ndarray | None = None

    def observation_space(self, agent: str) -> spaces.Space[Any]:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Discrete:
        return self._act_space

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        if seed is not None:
            self._np_random, _ = seeding.np_random(seed)
        self.world.reset(self._np_random)
        self.agents = list(self.possible_agents)
        self._last = None
        return self._observations(start=True), self._infos()

    def step(self, actions: dict[str, int]) -> tuple[dict[str, Any], dict[str, float], dict[str, bool],
                                                      dict[str, bool], dict[str, dict[str, Any]]]:
        if not self.agents:
            raise RuntimeError("the episode is over (or never began): call reset() first")
        rows = np.full(len(self.possible_agents), -1, np.int64)
        for agent, a in actions.items():
            i = self.possible_agents.index(agent)
            if not 0 <= int(a) < self._act_space.n:
                raise ValueError(f"action {a!r} of {agent} is outside {self._act_space}")
            rows[i] = int(a)
        w = self.world
        w.step(rows if len(rows) > 1 else int(rows[0]), self._np_random)  # one agent: its action, as an Env's
        self._last = rows
        terminated, truncated = w.terminated(), w.truncated()
        rewards = dict(zip(self.possible_agents, w.last_rewards))
        obs, infos = self._observations(), self._infos()
        if terminated or truncated:
            self.agents = []
        return (obs, rewards, dict.fromkeys(self.possible_agents, terminated),
                dict.fromkeys(self.possible_agents, truncated), infos)

    def _observations(self, start: bool = False) -> dict[str, Any]:
        """Each agent's observation (with its earlier ones: `start` begins an episode's)."""
        return {a: (h.start if start else h.step)(self.world.observation(i))
                for i, (a, h) in enumerate(zip(self.possible_agents, self._histories))}

    def _infos(self) -> dict[str, dict[str, Any]]:
        out = {}
        for i, a in enumerate(self.possible_agents):
            info: dict[str, Any] = {"t": self.world.steps}
            mask = self.world.action_mask(i)
            if mask is not None:
                info["action_mask"] = mask
            out[a] = info
        return out

    def render(self) -> str | np.ndarray | None:
        names = self.world_spec.action_names
        last = None if self._last is None else \
            ", ".join(f"{a}: {names[r] if r >= 0 else '-'}" for a, r in zip(self.possible_agents, self._last.tolist()))
        return render_world(self.world, self.render_mode, self._painter, last)
