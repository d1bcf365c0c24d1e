"""The oracle of the GridWar differential tests: RefSim (tracelab.game.refsim, the hand-written simulator)
played as the red team's gymnasium-style env, for the same seed and actions step by step against the
spec's envs (gym.make of tracelab/GridWar-*-v0, rules/gridworld/war*.toml).

reset(seed) -> (red's observation, info); step(action) -> (obs, red's team reward, terminated, truncated,
info). Actions are indices into the scenario's actions (one agent: an int; a team: one a agent). info holds
`action_mask` (ActionMasker, the shield computed from RefSim's state, which the tests compare with the
spec's mask rules) and, after a step, `winner` (0 red, 1 blue, 2 draw, -1 none), `opponent_actions` and
red's per-agent `unsafe`, `invalid`, `hits_made`, `hits_taken`, `agent_reward` (one agent: scalars)."""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from tracelab.game.refsim import RefSim
from tracelab.game.scenario import DIRECTION_DELTAS, DOWN, LEFT, NOTHING, RED, RIGHT, UP, Scenario, builtin_scenario
from tracelab.game.state import GameState


class ActionMasker:
    """Which learner actions are safe and valid in the current state, per world, team and agent.

    It mirrors the rules (rules/gridworld/game.rules): only an agent that may act gets a choice
    (t_fast / t_slow: alive, and a slow agent on even steps only; others can only do nothing, since
    the simulator ignores their actions); a move off the map (u_*_edge) or into a mountain (u_*_mtn) is
    masked, a shot with no ammo (s_empty, s_unarmed) is masked; do nothing is always allowed. It reads
    positions, ammo, alive and t from GameState and the map. It cannot
    foresee a bullet that kills the agent in phase 1 of the next step, before it acts.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.ids = np.asarray(scenario.action_ids, np.int64)
        self.n_actions = len(self.ids)
        # the layout both action sets share: moves at 0-3, shots at 4-7 (advanced), nothing last
        assert tuple(self.ids[:4]) == (UP, DOWN, LEFT, RIGHT) and self.ids[-1] == NOTHING
        self._shots = scenario.advanced
        # move_ok[x, y, d]: the move in direction d from (x, y) stays on the map and off the mountains
        w, h = scenario.width, scenario.height
        free = np.zeros((w + 2, h + 2), bool)  # padded with a blocked border
        free[1:-1, 1:-1] = ~scenario.mountain_grid
        x, y = np.meshgrid(np.arange(w), np.arange(h), indexing="ij")
        self._move_ok = np.stack([free[x + 1 + dx, y + 1 + dy] for dx, dy in DIRECTION_DELTAS], axis=-1)
        self._slow = scenario.slow_mask

    def __call__(self, state: GameState, team: int | None = None) -> np.ndarray:
        """int8 (gymnasium's mask dtype), 1 = allowed: [W, N, n_actions] for one team, or
        [W, 2, N, n_actions] for both (team=None)."""
        sel = slice(None) if team is None else team
        pos, can_act = state.pos[:, sel], state.choosing(self._slow)[:, sel]
        out = np.empty((*can_act.shape, self.n_actions), bool)
        out[..., :4] = self._move_ok[pos[..., 0], pos[..., 1]] & can_act[..., None]
        if self._shots:
            out[..., 4:8] = (can_act & (state.ammo[:, sel] > 0))[..., None]
        out[..., -1] = True
        return out.view(np.int8)


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
