"""How the observations of the env `train --env` / `eval --env` play (tracelab.envs.declared.env_source)
reach the network.

The network reads a flat float32 vector: a Discrete observation is one-hot encoded (FrozenLake's cell
index 5 of 16 becomes 16 numbers, a single 1 at 5), a MultiDiscrete one is its parts' one-hots side by
side, a Box is read as it is, flattened. A run and its policy record the env and its kwargs, so that an
evaluation or a resume on another env is refused (`check_same_env`)."""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from tracelab.errors import UserError

# deferred: the spec and the declared env (the engine's parser, numba), for a declared world's team only

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


class TeamEncoder:
    """Observations [W, agents, ...] of a world of several agents -> float32 [W * agents, size]: each agent's
    encoded observation, then its one-hot index (one network for every agent: env_policy.TeamPolicy)."""

    def __init__(self, agent_encoder: ObservationEncoder, n_agents: int) -> None:
        self.agent, self.n_agents = agent_encoder, n_agents
        self.size = agent_encoder.size + n_agents
        self._indicator = np.eye(n_agents, dtype=np.float32)

    def describe(self) -> str:
        return f"{self.agent.describe()} an agent, then its one-hot index among {self.n_agents} agents"

    def __call__(self, obs: Any) -> np.ndarray:
        each = self.agent(obs)  # [W * agents, D]: an agent's rows follow its world's order
        worlds = len(each) // self.n_agents
        return np.concatenate([each, np.tile(self._indicator, (worlds, 1))], axis=1)


def action_count(space: spaces.Space[Any], where: str) -> int:
    if not isinstance(space, spaces.Discrete):
        raise UserError(f"{where}: action space {space} is not Discrete: DQN picks one of n actions")
    return int(space.n)


def declared_spec(source: Any) -> Any:
    """The WorldSpec of a declared world (loaded with its [params]), else None."""
    from tracelab.envs.declared.spec import load_spec
    try:
        spec_path, params = source.declared()
    except UserError:  # not a declared world
        return None
    return load_spec(spec_path, **params)


def team_spec(source: Any) -> Any:
    """The WorldSpec of a declared world of several agents (trained as a team), else None."""
    spec = declared_spec(source)
    return spec if spec is not None and len(spec.agents) > 1 else None


def probe_env(source: Any, spec: Any = None) -> tuple[ObservationEncoder | TeamEncoder, int, Any]:
    """(the encoder of `source`'s observations, its action count, its WorldSpec or None): what sizes a
    training on it (a bad id, spec or keyword argument fails here, in one line). A declared world's spaces
    come from its spec alone (gym_env.DeclaredEnv's), so no engine is built for them: building one grounds the
    program and steps it, ~1 s of CPU for war.toml, which the command's own env then did again. Any other env
    is made and closed. A declared world of several agents: its TeamEncoder. `spec`: the declared world's
    WorldSpec where the caller loaded it already (a command parses its spec once)."""
    spec = spec if spec is not None else declared_spec(source)
    if spec is not None:
        from tracelab.envs.declared.gym_env import observation_space
        encoder = ObservationEncoder(observation_space(spec), source.name)
        n_actions = len(spec.action_names)
        return (TeamEncoder(encoder, len(spec.agents)) if len(spec.agents) > 1 else encoder), n_actions, spec
    probe = source.make()
    try:
        return (ObservationEncoder(probe.observation_space, source.name),
                action_count(probe.action_space, source.name), getattr(probe.unwrapped, "world_spec", None))
    finally:
        probe.close()
