"""Games of a declared world (a spec file or a registered id such as tracelab/FrozenLake-v1), played by a
random policy: the env resolved from what the user typed, its keyword arguments read from `key=value`
texts, and the play loop. `tracelab play --env` (tracelab/commands/play_env.py) records them into a run."""
from __future__ import annotations

import os
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.errors import UserError

DECLARED_ENTRY_POINT = "tracelab.envs.declared.gym_env:DeclaredEnv"


@dataclass(frozen=True)
class EnvSource:
    """Where a declared env comes from: a registered id (`env_id`) or a spec file (`spec_path`)."""
    text: str
    env_id: str | None
    spec_path: str  # the spec file (the id's, for an id)
    params: dict[str, Any]  # the spec's [params]: the id's fixed ones (map_name of FrozenLake8x8), the user's

    def load(self) -> WorldSpec:
        """The checked spec (SpecError, a located user error, for a wrong file or keyword argument)."""
        return load_spec(self.spec_path, **self.params)

    @property
    def name(self) -> str:
        """A short name for the run directory: the id without its namespace, or the spec's stem."""
        return self.env_id.split("/")[-1] if self.env_id else Path(self.spec_path).stem


def parse_env_args(texts: list[str]) -> dict[str, Any]:
    """`key=value` texts as keyword arguments; a value is read as a TOML value (false, 0.5, [1, 0, 0],
    "text") and otherwise kept as text (8x8)."""
    out: dict[str, Any] = {}
    for text in texts:
        key, eq, value = text.partition("=")
        key = key.strip()
        if not eq or not key.isidentifier():
            raise UserError(f"--env-arg {text!r}: expected key=value (write KEY=VALUE, e.g. is_slippery=false)")
        try:
            out[key] = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key] = value.strip()
    return out


def resolve_env(text: str, env_args: dict[str, Any]) -> EnvSource:
    """A registered id of a declared env, or the path of a spec file (UserError for anything else)."""
    import tracelab.envs  # noqa: F401 - registers the toy-text ids
    if text not in gym.registry and text.startswith("tracelab/"):
        import tracelab.envs.gym_env  # noqa: F401 - registers GridWar's ids, to say what they are
    if text in gym.registry:
        kwargs = dict(gym.registry[text].kwargs)
        if gym.registry[text].entry_point != DECLARED_ENTRY_POINT or "spec" not in kwargs:
            raise UserError(f"--env {text}: a registered env, but not one declared in rules (play --scenario "
                            "plays GridWar; --env takes a spec file or an id such as tracelab/FrozenLake-v1)")
        spec_path = str(kwargs.pop("spec"))
        return EnvSource(text, text, spec_path, {**kwargs, **env_args})
    if os.path.isfile(text):
        return EnvSource(text, None, text, env_args)
    declared = sorted(k for k, s in gym.registry.items() if s.entry_point == DECLARED_ENTRY_POINT)
    raise UserError(f"--env {text}: neither a spec file nor a registered id (the declared ids: {', '.join(declared)})")


def make_declared_env(source: EnvSource, spec: WorldSpec, **options: Any) -> gym.Env:
    """The env of `source` over its loaded `spec`, with `options` (kernel, trace_writer): an id through
    gym.make (its step limit, TimeLimit, which the traced env reads from its EnvSpec), a file as it is."""
    if source.env_id is not None:
        return gym.make(source.env_id, spec=spec, **options)
    from tracelab.envs.declared.gym_env import DeclaredEnv
    return DeclaredEnv(spec, **options)


def random_policy(env: gym.Env, seed: int) -> Callable[[Any, dict[str, Any]], int]:
    """Uniform over the actions (over the allowed ones when the env gives an action mask)."""
    rng = np.random.default_rng(seed)
    n = int(env.action_space.n)

    def act(obs: Any, info: dict[str, Any]) -> int:
        mask = info.get("action_mask")
        if mask is not None and mask.any():
            return int(rng.choice(np.flatnonzero(mask)))
        return int(rng.integers(0, n))
    return act


def play_episodes(env: gym.Env, episodes: int, seed: int, act: Callable[[Any, dict[str, Any]], int],
                  on_episode: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """Play `episodes` episodes (the first reset seeded with `seed`, the others continuing its stream);
    returns each episode's steps, return and outcome, the steps and the seconds they took."""
    out: list[dict[str, Any]] = []
    steps = 0
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    for e in range(episodes):
        if e:
            obs, info = env.reset()
        ret, n, terminated, truncated = 0.0, 0, False, False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, info = env.step(act(obs, info))
            ret += float(reward)
            n += 1
        steps += n
        out.append({"steps": n, "return": ret, "outcome": "terminated" if terminated else "truncated"})
        if on_episode is not None:
            on_episode(out[-1])
    return {"episodes": out, "steps": steps, "seconds": time.perf_counter() - t0}
