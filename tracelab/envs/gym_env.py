"""`GridWarEnv`: the grid-world war game as a gymnasium Env for the learner team (red), with the scripted
opponent (blue, tracelab/game/opponent.py) inside.

- Observation: red's observation (docs/game.md, Observations): 4 (base) or 7 (advanced) float32 numbers per
  agent, [current, previous] with `stack_previous` (the non-Markov setup).
- Action: an index into `scenario.action_ids` (Discrete(n_actions)) for one agent per team, one index
  per agent (MultiDiscrete([n_actions] * N)) for more.
- Reward: red's team reward, `StepResult.reward[:, 0]` (terms from the scenario's Rewards).
- `terminated` on a win, loss or draw; `truncated` at `scenario.max_steps`. Step again only after reset.
- info: `action_mask` (int8, [n_actions] or [N, n_actions]; see tracelab.envs.common.ActionMasker: the
  shield rules' atoms on the rules backend, the same mask computed from the state on the reference
  one), `t`, `winner` (refsim.WINNER_*: -1 none, 0 red, 1 blue, 2 draw), `opponent_actions` (blue's spec action
  ids in the step, -1 after reset), and red's per-agent `unsafe`, `invalid`, `hits_made`, `hits_taken`,
  `agent_reward` for the last step (zeros after reset). For MultiDiscrete, sample with
  `space.sample(mask=tuple(info["action_mask"]))`.
- Seeding: `reset(seed=s)` reseeds the opponent's generator; the same seed and actions give the same
  trajectory, with either backend.
- `backend`: "rules" (RuleSim, the rule engine) or "reference" (RefSim, the hand-written simulator).
- `trace_sink`: a TraceSink (tracelab/envs/sinks.py) receiving the trace; None builds the engine with its
  trace off.

Importing this module registers `tracelab/GridWar-{base,advanced,nonmarkov}-v0` (the last with
`stack_previous=True`; pass `stack_previous=False` for the Markov baseline), each with a vector entry
point (`gymnasium.make_vec` builds tracelab.envs.vector_env.GridWarVectorEnv).
"""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from tracelab.envs.common import (
    RENDER_FPS,
    RENDER_MODES,
    OneWorldEnv,
    learner_action_space,
    observation_space,
    reset_sim,
    step_learner,
)
from tracelab.envs.sinks import TraceSink
from tracelab.game.scenario import RED, Scenario
from tracelab.game.state import WINNER_NONE, StepResult

ENV_IDS = {name: f"tracelab/GridWar-{name}-v0" for name in ("base", "advanced", "nonmarkov")}


def step_info(res: StepResult, masks: np.ndarray, one_agent: bool, opponent: np.ndarray) -> dict[str, Any]:
    """info of every world after a step, arrays [W, ...] (red's view); masks: [W, N, n_actions];
    opponent: blue's actions (spec ids, [W, N]). With one agent per team the agent axis is dropped
    (masks [W, n_actions], events [W]). Every array is new: the StepResult's are the simulator's buffers."""
    info = {"action_mask": masks, "opponent_actions": np.asarray(opponent, np.int64),
            "unsafe": res.unsafe[:, RED].copy(), "invalid": res.invalid[:, RED].copy(),
            "hits_made": res.hits_made[:, RED].astype(np.int64),
            "hits_taken": res.hits_taken[:, RED].astype(np.int64), "agent_reward": res.agent_reward[:, RED].copy()}
    if one_agent:
        info = {k: v[:, 0] for k, v in info.items()}
    return {"t": res.t.astype(np.int64), "winner": res.winner.astype(np.int64), **info}


def reset_info(n_worlds: int, masks: np.ndarray, one_agent: bool) -> dict[str, Any]:
    """info of worlds at the start of an episode: nothing has happened yet."""
    shape = (n_worlds,) if one_agent else (n_worlds, masks.shape[1])
    return {"t": np.zeros(n_worlds, np.int64), "winner": np.full(n_worlds, WINNER_NONE, np.int64),
            "action_mask": masks[:, 0] if one_agent else masks, "opponent_actions": np.full(shape, -1, np.int64),
            "unsafe": np.zeros(shape, bool),
            "invalid": np.zeros(shape, bool), "hits_made": np.zeros(shape, np.int64),
            "hits_taken": np.zeros(shape, np.int64), "agent_reward": np.zeros(shape)}


class GridWarEnv(OneWorldEnv, gym.Env[np.ndarray, Any]):
    metadata = {"render_modes": RENDER_MODES, "render_fps": RENDER_FPS}

    def __init__(self, scenario: Scenario | str = "advanced", *, backend: str = "rules",
                 stack_previous: bool = False, trace_sink: TraceSink | None = None,
                 render_mode: str | None = None) -> None:
        self._set_up(scenario, backend, stack_previous, trace_sink, render_mode)
        self.observation_space = observation_space(self.scenario, stack_previous)
        self.action_space = learner_action_space(self.scenario)
        self._n = self.scenario.agents_per_team
        self._single = self._n == 1
        self._running = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        obs = reset_sim(self.sim, self._tracer, seed)
        self._running = True
        info = reset_info(1, self._masks(), self._single)
        return obs[0, RED].copy(), self._first(info)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if not self._running:
            raise RuntimeError("the episode is over (or never began): call reset() first")
        res, blue = step_learner(self.sim, self._masker, self._tracer, action, 1, self.action_space)
        terminated, truncated = bool(res.terminated[0]), bool(res.truncated[0])
        self._running = not (terminated or truncated)
        info = self._first(step_info(res, self._masks(), self._single, blue))
        return res.obs[0, RED].copy(), float(res.reward[0, RED]), terminated, truncated, info

    def _masks(self) -> np.ndarray:
        return self._masker.for_sim(self.sim, RED)

    @staticmethod
    def _first(info: dict[str, Any]) -> dict[str, Any]:
        """World 0's info: numpy scalars become Python scalars, arrays are copied out of the batch."""
        return {k: v[0].item() if v.ndim == 1 else v[0].copy() for k, v in info.items()}


def register_envs() -> None:
    """Register the built-in scenarios' env ids (idempotent)."""
    for name, env_id in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        kwargs: dict[str, Any] = {"scenario": name}
        if name == "nonmarkov":
            kwargs["stack_previous"] = True
        gym.register(id=env_id, entry_point="tracelab.envs.gym_env:GridWarEnv",
                     vector_entry_point="tracelab.envs.vector_env:GridWarVectorEnv", kwargs=kwargs)


register_envs()
