"""The environments: worlds declared by a spec beside a rule program (declared/, docs/worlds.md) as a
gymnasium Env, vector env and PettingZoo env: `make_env(SPEC, **kwargs)`, the ids of
rules/gridworld/war*.toml (declared/gridwar.py) and the toy-text games (`tracelab/FrozenLake-v1`,
...) registered with gymnasium. Every world is made this one way (docs/envs.md)."""
from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

from tracelab.envs.declared.gridwar import register_gridwar
from tracelab.envs.declared.toytext import register_toytext

if TYPE_CHECKING:
    from tracelab.envs.declared.gym_env import DeclaredEnv
    from tracelab.envs.declared.vector_env import DeclaredVectorEnv

# deferred: the declared envs (tracelab.envs.declared.*) load the engine (numba) when an env is made; importing
# tracelab.envs only registers the ids


def make_env(spec: str | os.PathLike[str], **kwargs: Any) -> DeclaredEnv:
    """The gymnasium Env a spec declares (docs/worlds.md); kwargs: the spec's [params], `render_mode`,
    `kernel` (the engine's)."""
    from tracelab.envs.declared.gym_env import DeclaredEnv
    return DeclaredEnv(spec, **kwargs)


def make_vec_env(spec: str | os.PathLike[str], num_envs: int, **kwargs: Any) -> DeclaredVectorEnv:
    """`num_envs` worlds of a spec as one gymnasium VectorEnv on one engine (SAME_STEP autoreset); kwargs:
    the spec's [params], `max_episode_steps`."""
    from tracelab.envs.declared.vector_env import DeclaredVectorEnv
    return DeclaredVectorEnv(spec, num_envs, **kwargs)


register_toytext()
register_gridwar()
