"""gymnasium's toy-text games written as rules (rules/toytext/), registered under tracelab's ids with
gymnasium's keyword arguments and episode limits. Each id builds a DeclaredEnv over its spec: the rules
hold every transition, reward and end; nothing here but where the spec is."""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym

from tracelab import RULES_DIR

TOYTEXT_DIR = RULES_DIR / "toytext"

# id -> (spec file, max_episode_steps as gymnasium registers its own game)
TOYTEXT_ENVS = {
    "tracelab/FrozenLake-v1": ("frozen_lake.toml", 100),
    "tracelab/FrozenLake8x8-v1": ("frozen_lake.toml", 200),
    "tracelab/CliffWalking-v1": ("cliff_walking.toml", None),
    "tracelab/CliffWalkingSlippery-v1": ("cliff_walking.toml", None),
    "tracelab/Taxi-v4": ("taxi.toml", 200),
}
_EXTRA_KWARGS = {"tracelab/FrozenLake8x8-v1": {"map_name": "8x8"},
                 "tracelab/CliffWalkingSlippery-v1": {"is_slippery": True}}


def spec_path(name: str) -> Path:
    return TOYTEXT_DIR / name


def register_toytext() -> None:
    """Register the toy-text ids (idempotent)."""
    for env_id, (spec, steps) in TOYTEXT_ENVS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point="tracelab.envs.declared.gym_env:DeclaredEnv",
                         vector_entry_point="tracelab.envs.declared.vector_env:DeclaredVectorEnv",
                         kwargs={"spec": str(spec_path(spec)), **_EXTRA_KWARGS.get(env_id, {})},
                         max_episode_steps=steps)
