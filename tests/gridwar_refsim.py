"""The oracle of the GridWar differential tests: RefSim (tracelab.game.refsim, the hand-written simulator)
played as the red team's gymnasium-style env, for the same seed and actions step by step against the
spec's envs (gym.make of tracelab/GridWar-*-v0, rules/gridworld/war*.toml).

reset(seed) -> (red's observation, info); step(action) -> (obs, red's team reward, terminated, truncated,
info). Actions are indices into the scenario's actions (one agent: an int; a team: one a agent). info holds
`action_mask` (ActionMasker, the shield computed from the state) and, after a step, `winner` (0 red,
1 blue, 2 draw, -1 none), `opponent_actions` and red's per-agent `unsafe`, `invalid`, `hits_made`,
`hits_taken`, `agent_reward` (one agent: scalars)."""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from tracelab.game.action_mask import ActionMasker
from tracelab.game.refsim import RefSim
from tracelab.game.scenario import RED, Scenario, builtin_scenario


class RefGridWar:
    def __init__(self, scenario: Scenario | str, stack_previous: bool = False) -> None:
        self.scenario = builtin_scenario(scenario) if isinstance(scenario, str) else scenario
        self.sim = RefSim(self.scenario, 1, seed=None, stack_previous=stack_previous)
        self.masker = ActionMasker(self.scenario)
        self._one = self.scenario.agents_per_team == 1
        self.action_space = spaces.Discrete(self.scenario.n_actions)  # each agent's

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        obs = self.sim.reset(seed=seed)
        return obs[0, RED].copy(), {"action_mask": self._mask()}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        red = self.masker.ids[np.asarray(action, np.int64).reshape(1, -1)]
        blue = self.sim.scripted_actions("blue")
        res = self.sim.step(red, blue)
        info: dict[str, Any] = {"action_mask": self._mask(), "winner": int(res.winner[0]),
                                "opponent_actions": self._agents(blue[0])}
        for key in ("unsafe", "invalid", "hits_made", "hits_taken", "agent_reward"):
            info[key] = self._agents(getattr(res, key)[0, RED])
        return (res.obs[0, RED].copy(), float(res.reward[0, RED]), bool(res.terminated[0]),
                bool(res.truncated[0]), info)

    def _mask(self) -> np.ndarray:
        masks = self.masker(self.sim.state, RED)[0]
        return masks[0] if self._one else masks

    def _agents(self, values: np.ndarray) -> Any:
        return values[0].item() if self._one else values.copy()
