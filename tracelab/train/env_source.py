"""Which gymnasium env `train --env` / `eval --env` play: a registered id or a spec file, with keyword
arguments, and how its observations reach the network.

The network reads a flat float32 vector: a Discrete observation is one-hot encoded (FrozenLake's cell
index 5 of 16 becomes 16 numbers, a single 1 at 5), a MultiDiscrete one is its parts' one-hots side by
side, a Box is read as it is, flattened. A run and its policy record the env and its kwargs, so that an
evaluation or a resume on another env is refused (`check_same_env`)."""
from __future__ import annotations

import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from tracelab.envs.declared.play import parse_env_args  # noqa: F401 (--env-arg, one parser for play and train)
from tracelab.errors import UserError


@dataclass(frozen=True)
class EnvSource:
    name: str                                  # a registered id (tracelab/FrozenLake-v1) or a spec path
    kwargs: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def given(cls, name: str, kwargs: dict[str, Any]) -> "EnvSource":
        """As the user names it: a spec file by its absolute path (a run or policy then names the same file
        from any folder), an id as it is."""
        import gymnasium as gym
        import tracelab.envs  # noqa: F401  (registers the toy-text ids)
        if name not in gym.registry and Path(name).is_file():
            name = str(Path(name).resolve())
        return cls(name, kwargs)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "kwargs": dict(self.kwargs)}

    def describe(self) -> str:
        """As the command line gives it: `tracelab/FrozenLake-v1 --env-arg is_slippery=false`."""
        return " ".join([shlex.quote(self.name),
                         *(f"--env-arg {shlex.quote(f'{k}={_toml_value(v)}')}" for k, v in self.kwargs.items())])

    def make(self) -> Any:
        """A new env (gym.make for a registered id: its TimeLimit and checks; make_env for a spec file)."""
        import gymnasium as gym
        import tracelab.envs  # noqa: F401  (registers the toy-text ids)
        if self.name in gym.registry:
            return gym.make(self.name, **self.kwargs)
        if not Path(self.name).is_file():
            known = sorted(k for k in gym.registry if k.startswith("tracelab/"))
            raise UserError(f"--env {self.name!r}: neither a registered env id ({', '.join(known)}, or "
                            f"gymnasium's) nor a spec file")
        return tracelab.envs.make_env(self.name, **self.kwargs)


def _toml_value(value: Any) -> str:
    """A kwarg's value as --env-arg reads it back (TOML: true, 0.5, "8x8", ["SF", "HG"])."""
    return str(value).lower() if isinstance(value, bool) else json.dumps(value)


def env_source_from_json(d: Any, where: str) -> EnvSource:
    if not (isinstance(d, dict) and isinstance(d.get("name"), str) and isinstance(d.get("kwargs", {}), dict)):
        raise UserError(f"{where}: env: expected {{\"name\": str, \"kwargs\": {{...}}}}, got {str(d)[:80]}")
    return EnvSource(d["name"], dict(d.get("kwargs", {})))


def check_same_env(recorded: EnvSource, given: EnvSource, what: str) -> None:
    """One line naming both when `given` is not the env `what` (a policy, a checkpoint) was trained on."""
    if (recorded.name, recorded.kwargs) != (given.name, given.kwargs):
        raise UserError(f"{what} was trained on --env {recorded.describe()}, not {given.describe()}")


MAX_INPUTS = 1_000_000  # network inputs: a spec's Discrete(10**9) is refused before anything is built


class ObservationEncoder:
    """A batch of observations of `space` -> float32 [K, size], the network's input."""

    def __init__(self, space: spaces.Space[Any], where: str) -> None:
        self._read(space, where)
        if self.size > MAX_INPUTS:
            raise UserError(f"{where}: observation space {space} makes {self.size:,} network inputs (one-hot); "
                            f"DQN here reads at most {MAX_INPUTS:,}")

    def _read(self, space: spaces.Space[Any], where: str) -> None:
        if isinstance(space, spaces.Discrete):
            self.kind, self.size, self.n = "onehot", int(space.n), int(space.n)
            self.start = int(space.start)
        elif isinstance(space, spaces.MultiDiscrete) and space.nvec.ndim == 1:
            self.kind, self.size = "onehots", int(space.nvec.sum())
            self.offsets = np.concatenate([[0], np.cumsum(space.nvec)[:-1]]).astype(np.int64)
        elif isinstance(space, spaces.Box):
            self.kind, self.size = "box", int(np.prod(space.shape))
        else:
            raise UserError(f"{where}: observation space {space} is not one DQN reads here (Discrete, "
                            f"MultiDiscrete or Box)")

    def describe(self) -> str:
        return {"onehot": f"Discrete({self.size}) one-hot", "onehots": f"MultiDiscrete one-hots ({self.size})",
                "box": f"Box, {self.size} numbers"}[self.kind]

    def __call__(self, obs: Any) -> np.ndarray:
        if self.kind == "box":
            return np.asarray(obs, np.float32).reshape(-1, self.size)
        idx = np.asarray(obs, np.int64)
        if self.kind == "onehot":
            idx = idx.reshape(-1)
            out = np.zeros((len(idx), self.size), np.float32)
            out[np.arange(len(idx)), idx - self.start] = 1.0
            return out
        idx = idx.reshape(-1, len(self.offsets)) + self.offsets
        out = np.zeros((len(idx), self.size), np.float32)
        np.put_along_axis(out, idx, 1.0, axis=1)
        return out


def action_count(space: spaces.Space[Any], where: str) -> int:
    if not isinstance(space, spaces.Discrete):
        raise UserError(f"{where}: action space {space} is not Discrete: DQN picks one of n actions")
    return int(space.n)
