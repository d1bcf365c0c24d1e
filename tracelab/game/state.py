"""The game's state in W worlds and what one step hands out: RefSim's data. The layout of every array
is in tracelab/game/refsim.py's module docstring."""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from .scenario import Scenario

WINNER_NONE, WINNER_RED, WINNER_BLUE, WINNER_DRAW = -1, 0, 1, 2


# ----------------------------------------------------------------------------------------------------
# State and results
# ----------------------------------------------------------------------------------------------------
@dataclass(slots=True)
class GameState:
    """Mutable state of W worlds (layout in the module docstring)."""
    t: np.ndarray
    pos: np.ndarray
    health: np.ndarray
    ammo: np.ndarray
    alive: np.ndarray
    moving: np.ndarray
    dest: np.ndarray
    bullet_pos: np.ndarray
    bullet_dir: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    winner: np.ndarray
    bullet_team: np.ndarray   # [B] owner team per slot (constant)
    bullet_agent: np.ndarray  # [B] owner agent per slot (constant)

    @classmethod
    def initial(cls, scenario: Scenario, n_worlds: int) -> "GameState":
        n, a = scenario.agents_per_team, scenario.ammo
        n_b = 2 * n * a
        pos = np.empty((n_worlds, 2, n, 2), dtype=np.int32)
        pos[:, 0] = np.asarray(scenario.red_starts, dtype=np.int32)
        pos[:, 1] = np.asarray(scenario.blue_starts, dtype=np.int32)
        slots = np.arange(n_b)
        return cls(
            t=np.zeros(n_worlds, dtype=np.int32),
            pos=pos,
            health=np.full((n_worlds, 2, n), scenario.health, dtype=np.float64),
            ammo=np.full((n_worlds, 2, n), a, dtype=np.int32),
            alive=np.ones((n_worlds, 2, n), dtype=bool),
            moving=np.zeros((n_worlds, 2, n), dtype=bool),
            dest=np.full((n_worlds, 2, n, 2), -1, dtype=np.int32),
            bullet_pos=np.full((n_worlds, n_b, 2), -1, dtype=np.int32),
            bullet_dir=np.full((n_worlds, n_b), -1, dtype=np.int8),
            terminated=np.zeros(n_worlds, dtype=bool),
            truncated=np.zeros(n_worlds, dtype=bool),
            winner=np.full(n_worlds, WINNER_NONE, dtype=np.int8),
            bullet_team=(slots // max(n * a, 1)).astype(np.int8),
            bullet_agent=((slots // max(a, 1)) % n).astype(np.int16),
        )

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated

    def choosing(self, slow_mask: np.ndarray) -> np.ndarray:
        """bool [W, 2, N]: the agents whose action choice the game takes this step (game.rules t_fast /
        t_slow): alive, not in transit, and a slow agent (`slow_mask` [2, N], Scenario.slow_mask) on even
        steps only; the simulators ignore the others' actions."""
        can = self.alive & ~self.moving
        if slow_mask.any():
            can &= ~slow_mask | (self.t % 2 == 0)[:, None, None]
        return can

    def copy(self) -> "GameState":
        return GameState(**{f.name: getattr(self, f.name).copy() for f in fields(self)})

    def assign(self, other: "GameState", worlds: np.ndarray) -> None:
        """Copy the given worlds (mask or indices) from `other`, which has the same shapes."""
        for f in fields(self):
            if f.name not in ("bullet_team", "bullet_agent"):
                getattr(self, f.name)[worlds] = getattr(other, f.name)[worlds]


# not frozen: a frozen dataclass's __init__ costs more per step (docs/benchmarks.md, "Figures behind the code")
@dataclass(slots=True)
class StepResult:
    """Everything one batched step produced; arrays are [W, ...]. By default (a simulator built with
    copy=False) they are read-only views of the simulator's buffers, valid until its next step or reset:
    keep what you need with `copy()` (or build the simulator with copy=True, then every step returns new
    arrays)."""
    obs: np.ndarray           # float32 [W, 2, D]: observation of each team (docs/game.md)
    positions: np.ndarray     # int32 [W, 2, N, 2] after the step (dead agents: where they died)
    health: np.ndarray        # float64 [W, 2, N]
    ammo: np.ndarray          # int32 [W, 2, N]
    alive: np.ndarray         # bool [W, 2, N]
    moving: np.ndarray        # bool [W, 2, N]: slow agent between the two steps of a move
    move_dest: np.ndarray     # int32 [W, 2, N, 2]: where a moving slow agent arrives, else (-1,-1)
    bullet_pos: np.ndarray    # int32 [W, B, 2], (-1,-1) in empty slots
    bullet_dir: np.ndarray    # int8 [W, B], -1 in empty slots
    bullet_owner: np.ndarray  # int [B, 2]: (team, agent) of each slot
    unsafe: np.ndarray        # bool [W, 2, N]: move into a mountain / off the map (shielded)
    invalid: np.ndarray       # bool [W, 2, N]: shot with no ammo
    hits_made: np.ndarray     # int32 [W, 2, N]: enemies this agent's bullets hit this step
    hits_taken: np.ndarray    # int32 [W, 2, N]: bullets that hit this agent this step
    agent_reward: np.ndarray  # float64 [W, 2, N]: own per-step terms + the team's terminal term
    reward: np.ndarray        # float64 [W, 2]: team reward (sum of per-step terms + terminal once)
    terminated: np.ndarray    # bool [W]: game over by capture / elimination (stays True until reset)
    truncated: np.ndarray     # bool [W]: step limit reached without a winner (stays True until reset)
    winner: np.ndarray        # int8 [W]: WINNER_NONE / RED / BLUE / DRAW
    t: np.ndarray             # int32 [W]: steps taken

    def copy(self) -> "StepResult":
        """The same result in new, writable arrays that no later step changes."""
        return StepResult(**{f.name: getattr(self, f.name).copy() for f in fields(self)})

    @property
    def bullet_live(self) -> np.ndarray:
        return self.bullet_dir >= 0

    @property
    def hit_opponent(self) -> np.ndarray:
        return self.hits_made > 0

    @property
    def got_shot(self) -> np.ndarray:
        return self.hits_taken > 0

    @property
    def done(self) -> np.ndarray:
        return self.terminated | self.truncated

