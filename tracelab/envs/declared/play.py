"""Games of a declared world (a spec file or a registered id such as tracelab/FrozenLake-v1, an
env_source.EnvSource), played by a random policy: its spec, its env, and the play loop. `tracelab play
--env` (tracelab/commands/play_env.py) records them into a run."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.spec import WorldSpec, load_spec


def make_declared_env(source: EnvSource, spec: WorldSpec, **options: Any) -> gym.Env:
    """The env of `source` over its loaded `spec`, with `options` (kernel, trace_writer): an id through
    gym.make (its step limit, TimeLimit, which the traced env reads from its EnvSpec), a file as it is."""
    if source.env_id is not None:
        return gym.make(source.env_id, spec=spec, **options)
    # deferred: the declared env loads the engine (numba); a registered id goes through gym.make
    from tracelab.envs.declared.gym_env import DeclaredEnv
    return DeclaredEnv(spec, **options)


def load_declared(source: EnvSource) -> WorldSpec:
    """The checked spec of a declared world (SpecError, a located user error, for a wrong file or keyword
    argument; UserError for a source that is not a declared world)."""
    spec_path, params = source.declared()
    return load_spec(spec_path, **params)


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
                  on_episode: Callable[[dict[str, Any]], None] | None = None,
                  step_cap: int | None = None) -> dict[str, Any]:
    """Play `episodes` episodes (the first reset seeded with `seed`, the others continuing its stream);
    returns each episode's steps, return and outcome, the steps and the seconds they took. `step_cap`: an
    episode still running after that many steps ends there, counted truncated (a traced one's record ends
    'aborted' at the next reset)."""
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
            truncated = truncated or (step_cap is not None and n >= step_cap and not terminated)
        steps += n
        # the env's own outcome where the world declares a win ([end] win: "win" or "loss")
        outcome = info.get("outcome", "terminated") if terminated else "truncated"
        out.append({"steps": n, "return": ret, "outcome": outcome})
        if on_episode is not None:
            on_episode(out[-1])
    return {"episodes": out, "steps": steps, "seconds": time.perf_counter() - t0}
