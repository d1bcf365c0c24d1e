"""`[observation] previous = N` (docs/worlds.md): each observation followed by those of the N steps
before it, as RuleSim's `stack_previous` gives them (N = 1): at a reset every earlier observation is the
start's own; after a step they move back by one. Kept per world (a batch: the first axis of each array),
so the one-world env, the PettingZoo env (one per agent) and the vector env share it."""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces


def previous_name(k: int, name: str) -> str:
    """A Dict entry's name k steps back (k = 1: `previous_{name}`)."""
    return f"previous_{name}" if k == 1 else f"previous{k}_{name}"


def stacked_space(space: spaces.Space[Any], depth: int) -> spaces.Space[Any]:
    """The space of an observation of `space` followed by `depth` earlier ones."""
    if depth == 0:
        return space
    if isinstance(space, spaces.Box):
        return spaces.Box(np.tile(space.low, depth + 1), np.tile(space.high, depth + 1), dtype=space.dtype)
    if isinstance(space, spaces.MultiDiscrete):
        return spaces.MultiDiscrete(np.tile(space.nvec, depth + 1))
    if isinstance(space, spaces.Dict):
        entries = dict(space.spaces)
        for k in range(1, depth + 1):
            entries.update({previous_name(k, n): s for n, s in space.spaces.items()})
        return spaces.Dict(entries)
    raise ValueError(f"no earlier observations for a {type(space).__name__} space")  # spec.py refuses it first


class ObservationHistory:
    """The current observation and the `depth` before it, of one world or of a batch (arrays with a world
    axis first, or a dict of them for a Dict space)."""

    def __init__(self, depth: int) -> None:
        self.depth = depth
        self._now: Any = None  # the current observation, as read (not stacked)
        self._past: list[Any] = []  # [k]: the observation k + 1 steps back

    def start(self, obs: Any, worlds: np.ndarray | None = None) -> Any:
        """Worlds `worlds` (every one when None) begin an episode, `obs` being every world's current
        observation: their earlier observations become their start's. Returns the stacked observation."""
        if self.depth == 0:
            return obs
        if worlds is None or self._now is None:
            self._now = _copy(obs)
            self._past = [_copy(obs) for _ in range(self.depth)]
        else:
            for kept in (self._now, *self._past):
                _assign(kept, obs, worlds)
        return self._stack()

    def step(self, obs: Any) -> Any:
        """After a step of every world: the current observation moves back by one, `obs` is the new one.
        Returns the stacked observation."""
        if self.depth == 0:
            return obs
        self._past = [self._now, *self._past[:-1]]
        self._now = _copy(obs)
        return self._stack()

    def _stack(self) -> Any:
        if isinstance(self._now, dict):
            out = _copy(self._now)
            for k, past in enumerate(self._past, start=1):
                out.update({previous_name(k, n): v for n, v in _copy(past).items()})
            return out
        return np.concatenate([self._now, *self._past], axis=-1)


def _copy(obs: Any) -> Any:
    if isinstance(obs, dict):
        return {n: v.copy() if isinstance(v, np.ndarray) else v for n, v in obs.items()}
    return np.array(obs)


def _assign(kept: Any, obs: Any, worlds: np.ndarray) -> None:
    if isinstance(kept, dict):
        for n in kept:
            kept[n][worlds] = obs[n][worlds]
    else:
        kept[worlds] = obs[worlds]
