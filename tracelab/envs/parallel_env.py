"""`GridWarParallelEnv`: the game as a PettingZoo ParallelEnv, every agent of both teams a player.

- Agents are named like the engine's nodes: `red-agent-1`, ..., `blue-agent-1`, ...
- Each agent observes its team's observation (docs/game.md: own team's positions first, then the
  opponent's; [current, previous] with `stack_previous`); all agents of a team see the same numbers.
- Actions: Discrete(n_actions), an index into `scenario.action_ids`; an agent left out of the actions
  dict does nothing.
- Rewards: each agent's own `StepResult.agent_reward` (its own terms plus its team's terminal term).
- Dead agents stay in `agents` until the game ends (the terminal term is theirs too); their action mask
  allows only "do nothing". When the game ends every agent is terminated (win, loss, draw) or truncated
  (step limit), and `agents` becomes empty; step again only after reset.
- infos[agent]: `action_mask` (int8 [n_actions], tracelab.envs.common.ActionMasker), `unsafe`, `invalid`,
  `hits_made`, `hits_taken` of the last step, and `alive`.
- `backend` and `trace_sink` as in tracelab.envs.gym_env.GridWarEnv; the trace's step records carry both teams.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from tracelab.envs.common import (
    RENDER_FPS,
    RENDER_MODES,
    OneWorldEnv,
    observation_space,
    reset_sim,
)
from tracelab.envs.sinks import TraceSink
from tracelab.game.facts import agent_name
from tracelab.game.scenario import NOTHING, Scenario


class GridWarParallelEnv(OneWorldEnv, ParallelEnv[str, np.ndarray, int]):
    metadata = {"name": "tracelab_gridwar_v0", "render_modes": RENDER_MODES, "render_fps": RENDER_FPS,
                "is_parallelizable": True}

    def __init__(self, scenario: Scenario | str = "advanced", *, backend: str = "rules",
                 stack_previous: bool = False, trace_sink: TraceSink | None = None,
                 render_mode: str | None = None) -> None:
        self._set_up(scenario, backend, stack_previous, trace_sink, render_mode)
        n = self.scenario.agents_per_team
        self.possible_agents = [agent_name(t, j) for t in range(2) for j in range(n)]
        self.agents: list[str] = []
        self._team = np.repeat([0, 1], n)   # per agent, in possible_agents order
        self._slot = np.tile(np.arange(n), 2)
        self._obs_space = observation_space(self.scenario, stack_previous)
        low, high = (np.concatenate([b, b]) for b in (self._obs_space.low, self._obs_space.high))
        self.state_space = spaces.Box(low, high, dtype=np.float32)  # both teams' observations
        self._act_space = {a: spaces.Discrete(self.scenario.n_actions) for a in self.possible_agents}
        self._nothing = int(np.flatnonzero(self._masker.ids == NOTHING)[0])
        self._index = {a: i for i, a in enumerate(self.possible_agents)}

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Discrete:
        return self._act_space[agent]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        obs = reset_sim(self.sim, self._tracer, seed)[0]
        self.agents = list(self.possible_agents)
        zeros = np.zeros((2, self.scenario.agents_per_team), np.int64)
        return self._per_agent(obs), self._infos(zeros.astype(bool), zeros.astype(bool), zeros, zeros)

    def step(self, actions: dict[str, int]) -> tuple[dict[str, np.ndarray], dict[str, float], dict[str, bool],
                                                      dict[str, bool], dict[str, dict[str, Any]]]:
        if not self.agents:
            raise RuntimeError("the game is over (or never began): call reset() first")
        idx = np.full(len(self.possible_agents), self._nothing, np.int64)
        for agent, a in actions.items():
            idx[self._index[agent]] = a
        if ((idx < 0) | (idx >= self.scenario.n_actions)).any():
            raise ValueError(f"actions {actions} outside Discrete({self.scenario.n_actions})")
        acts = self._masker.ids[idx].reshape(1, 2, -1)
        res = self.sim.step(acts[:, 0], acts[:, 1])
        if self._tracer is not None:
            self._tracer.stepped(res, acts[:, 0], acts[:, 1])
        rewards = dict(zip(self.possible_agents, res.agent_reward[0].ravel().tolist()))
        terminated = dict.fromkeys(self.possible_agents, bool(res.terminated[0]))
        truncated = dict.fromkeys(self.possible_agents, bool(res.truncated[0]))
        obs = self._per_agent(res.obs[0])
        infos = self._infos(res.unsafe[0], res.invalid[0], res.hits_made[0], res.hits_taken[0])
        if res.terminated[0] or res.truncated[0]:
            self.agents = []
        return obs, rewards, terminated, truncated, infos

    def _per_agent(self, team_obs: np.ndarray) -> dict[str, np.ndarray]:
        return {a: team_obs[t].copy() for a, t in zip(self.possible_agents, self._team)}

    def _infos(self, unsafe: np.ndarray, invalid: np.ndarray, hits_made: np.ndarray,
               hits_taken: np.ndarray) -> dict[str, dict[str, Any]]:
        state = self.sim.state
        masks = self._masker.for_sim(self.sim)[0]
        alive = state.alive[0]
        return {a: {"action_mask": masks[t, j], "unsafe": bool(unsafe[t, j]), "invalid": bool(invalid[t, j]),
                    "hits_made": int(hits_made[t, j]), "hits_taken": int(hits_taken[t, j]),
                    "alive": bool(alive[t, j])}
                for a, t, j in zip(self.possible_agents, self._team, self._slot)}

    def state(self) -> np.ndarray:
        """Both teams' current observations, concatenated (red's, then blue's)."""
        return np.concatenate([self.sim.observe("red")[0], self.sim.observe("blue")[0]])
