"""ActionMasker: GridWar's action mask (the shield) computed from RefSim's state (the hand-written
oracle's; tests/gridwar_refsim.py), which the differential tests compare with the spec's mask rules."""
from __future__ import annotations

import numpy as np

from tracelab.game.scenario import DIRECTION_DELTAS, DOWN, LEFT, NOTHING, RIGHT, UP, Scenario
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
