"""RefSim's base: the set-up of its fields, the step contract (buffers, or copies with `copy=True`),
the observations it hands out, and the scripted policy on its state."""
from __future__ import annotations

import numpy as np

from tracelab.game.observe import obs_size, observe_both
from tracelab.game.opponent import P_TOWARD, TeamPolicy
from tracelab.game.scenario import Scenario, team_index
from tracelab.game.state import StepResult


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of a simulator's buffer: what it hands out (made once, valid until the next
    step or reset overwrites the buffer)."""
    v = a.view()
    v.flags.writeable = False
    return v


class GameSim:
    """Base of RefSim (RuleSim, the rule-driven simulator deleted on 2026-11-29, was the other).
    Subclasses keep `self.state` (a GameState), `self._obs` (the
    observation buffer handed out, [W, 2, D]), `self._result` (the StepResult of read-only views of
    their buffers, handed out by every step) and `self._policy_state` (the writable pos, alive, ammo
    arrays the scripted policy reads).

    The step contract (the convention of batched RL envs): with `copy=False` (the default) the arrays
    of a StepResult and of reset()'s observation are read-only views of buffers the simulator owns and
    overwrites at its next step or reset; with `copy=True` every step and reset returns new arrays that
    nothing changes later."""

    def __init__(self, scenario: Scenario, n_worlds: int, seed: int | None, stack_previous: bool,
                 copy: bool) -> None:
        if n_worlds < 1:
            raise ValueError(f"n_worlds must be at least 1, got {n_worlds}")
        self.scenario = scenario
        self.n_worlds = n_worlds
        self.stack_previous = stack_previous
        self.copy = copy
        self.rng = np.random.default_rng(seed)
        self.obs_size = obs_size(scenario, stack_previous)
        self.opponent_p = P_TOWARD  # the scripted policy's probability of a move towards the enemy base
        self._policy = TeamPolicy(scenario, n_worlds)

    def _observe_both(self, state) -> np.ndarray:
        """Both teams' observations of `state` without history, [W, 2, D]."""
        return observe_both(state, self.scenario)

    def _with_history(self, cur: np.ndarray, prev: np.ndarray) -> np.ndarray:
        return np.concatenate([cur, prev], axis=2) if self.stack_previous else cur

    def _reset_obs(self, worlds: np.ndarray | slice) -> np.ndarray:
        """After the state of `worlds` was reset: their observation becomes the start's (history at a
        reset: the current observation); returns what reset() hands out."""
        cur = self._observe_both(self.state)
        self._obs[worlds] = self._with_history(cur, cur)[worlds]
        return self._handed_obs()

    def _handed_obs(self) -> np.ndarray:
        """What reset() returns: the observation buffer (read-only), or its copy."""
        return self._obs.copy() if self.copy else self._obs_view

    def _handed_out(self) -> StepResult:
        """What step() returns: the result of buffers, or its copy."""
        return self._result.copy() if self.copy else self._result

    def observe(self, team: int | str) -> np.ndarray:
        """The last observation of one team (from reset or step), [W, D]."""
        return self._obs[:, team_index(team)].copy()

    def scripted_actions(self, team: int | str = "blue") -> np.ndarray:
        """The scripted policy's actions for `team` in the current state, drawn from `self.rng` (new
        int64 [W, N])."""
        pos, alive, ammo = self._policy_state
        return self._policy(pos, alive, ammo, team_index(team), self.rng, float(self.opponent_p))
