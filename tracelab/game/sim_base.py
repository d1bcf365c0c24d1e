"""What the two simulators (RefSim, hand-written; RuleSim, rule-driven) share: the set-up of their
common fields, the observations they hand out, and the scripted policy on their state."""
from __future__ import annotations

import numpy as np

from tracelab.game.observe import obs_size, observe_both
from tracelab.game.opponent import P_TOWARD, scripted_actions
from tracelab.game.scenario import Scenario, team_index


class GameSim:
    """Base of RefSim and RuleSim. Subclasses keep `self.state` (a refsim.GameState) and `self._obs`
    (the last observation handed out, [W, 2, D])."""

    def __init__(self, scenario: Scenario, n_worlds: int, seed: int | None, stack_previous: bool) -> None:
        if n_worlds < 1:
            raise ValueError(f"n_worlds must be at least 1, got {n_worlds}")
        self.scenario = scenario
        self.n_worlds = n_worlds
        self.stack_previous = stack_previous
        self.rng = np.random.default_rng(seed)
        self.obs_size = obs_size(scenario, stack_previous)
        self.opponent_p = P_TOWARD  # the scripted policy's probability of a move towards the enemy base

    def _observe_both(self, state) -> np.ndarray:
        """Both teams' observations of `state` without history, [W, 2, D]."""
        return observe_both(state, self.scenario)

    def _with_history(self, cur: np.ndarray, prev: np.ndarray) -> np.ndarray:
        return np.concatenate([cur, prev], axis=2) if self.stack_previous else cur

    def observe(self, team: int | str) -> np.ndarray:
        """The last observation of one team (from reset or step), [W, D]."""
        return self._obs[:, team_index(team)].copy()

    def scripted_actions(self, team: int | str = "blue") -> np.ndarray:
        """The scripted policy's actions for `team` in the current state, drawn from `self.rng`."""
        s = self.state
        return scripted_actions(s.pos, s.alive, s.ammo, team, self.scenario, self.rng, self.opponent_p)
