"""`DeclaredVectorEnv`: `num_envs` worlds of a spec (docs/worlds.md) as one gymnasium VectorEnv, every world
stepped by one engine call (vector_world.DeclaredWorlds). Spaces, rewards and infos are DeclaredEnv's,
batched (gymnasium.vector.utils.batch_space).

Autoreset: SAME_STEP, as gymnasium's SyncVectorEnv with autoreset_mode=SAME_STEP: a world whose episode
ends returns its terminal reward and flags but its reset observation; info["final_obs"] (the
observations' dtype and shape, valid where info["_final_obs"]) holds the terminal observations,
info["final_info"] the step's info of those worlds (each key with its `_key` mask, the worlds that
ended), info["_final_info"] marks them; the top-level info describes the returned observation (for a
reset world: t = 0 and the new episode's action_mask). Every key has its `_key` mask.

Seeding, as SyncVectorEnv seeds its envs: reset(seed=s) seeds world i's np_random with s + i, a list
seeds world i with seed[i]; a world that restarts later draws on from its own generator. So world i
steps exactly as DeclaredEnv (and gymnasium's own game) reset with seed s + i and given its actions.

`kernel`: the engine's; "auto" takes the lanes kernel from 64 worlds on (bit-parallel, one call for all
worlds) and counting below (every world in one compiled call with the reads, vector_fused.py).

`max_episode_steps`: truncation after that many steps (gymnasium's TimeLimit; make_vec passes the
registered limit).

Several agents (a spec whose `[agents] names` are more than one, an array observation): the worlds as a
team env, as play.TeamEnv steps one world: observations [W, agents, ...] (each agent's, read with `Agent` =
it), actions [W, agents] (-1: the agent does nothing, as one left out of a PettingZoo step), the reward
[W] the agents' sum and info["agent_reward"] [W, agents] each one's (the step's, also for a world that
ended), info["action_mask"] [W, agents, actions]; where the spec declares `[agents] decides` and `alive`,
info["decides"] and info["alive"] [W, agents] (the returned observation's state; final_info holds the ended
worlds' last ones). What the trainer trains a team on (env_trainer.py), and what gym.make_vec of a war.toml
id with several agents a team builds (gridwar.make_vec_env)."""
from __future__ import annotations

import os
from typing import Any, Sequence

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from tracelab.envs.declared.gym_env import observation_space
from tracelab.envs.declared.history import ObservationHistory
from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.envs.declared.vector_world import DeclaredWorlds


def with_masks(info: dict[str, Any], mask: np.ndarray) -> dict[str, Any]:
    """gymnasium's vector info layout: each key with a `_key` bool mask of the worlds it covers."""
    out = dict(info)
    for key in info:
        if not key.startswith("_"):
            out.setdefault(f"_{key}", mask)
    return out


class DeclaredVectorEnv(VectorEnv):
    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, spec: WorldSpec | str | os.PathLike[str], num_envs: int = 1, *,
                 max_episode_steps: int | None = None, render_mode: str | None = None, copy: bool = True,
                 kernel: str = "auto", **params: Any) -> None:
        if render_mode is not None:
            raise ValueError("DeclaredVectorEnv does not render")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be at least 1, got {max_episode_steps}")
        self.world_spec = spec if isinstance(spec, WorldSpec) else load_spec(spec, **params)
        self.n_agents = n = len(self.world_spec.agents)
        if n > 1 and self.world_spec.space == "Dict":
            raise ValueError(f"{self.world_spec.path}: the vector env plays several agents of an array "
                             f"observation (Box, Discrete, MultiDiscrete); this spec's is a Dict")
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.copy = copy  # observations are new arrays either way; kept for SyncVectorEnv's signature
        self.worlds = DeclaredWorlds(self.world_spec, num_envs, kernel)
        self.agent_observation_space = observation_space(self.world_spec)  # each agent's
        n_actions = len(self.world_spec.action_names)
        self.single_observation_space = self.agent_observation_space if n == 1 else \
            batch_space(self.agent_observation_space, n)
        self.single_action_space = spaces.Discrete(n_actions) if n == 1 else spaces.MultiDiscrete([n_actions] * n)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._rngs: list[np.random.Generator] = []
        self._all = np.ones(num_envs, bool)
        self._all.flags.writeable = False  # shared by every `_key` mask that covers all worlds
        self._everywhere = np.arange(num_envs)
        self._histories = [ObservationHistory(self.world_spec.previous) for _ in range(n)]
        one = self.worlds.one
        self._flags = {"decides": one._decides_ids, "alive": one._alive_ids}  # [agents] decides, alive

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        mask = (options or {}).get("reset_mask")
        if mask is not None and self._rngs:  # only these worlds restart, drawing on from their generators
            reset = np.flatnonzero(np.asarray(mask, bool))
            self.worlds.reset(reset)
            return self._observe(reset), self._info(self._all)
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = [None if s is None else int(s) for s in seed]
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset(seed=...) needs one seed per world ({self.num_envs}), got {len(seeds)}")
        if seed is not None or not self._rngs:
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
            self.worlds.use_generators(self._rngs)
        if isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
        self.worlds.reset(self._everywhere)
        return self._observe(self._everywhere), self._info(self._all)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._rngs:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(actions)
        n, shape = len(self.world_spec.action_names), (self.num_envs,) + ((self.n_agents,) if self.n_agents > 1 else ())
        low = -1 if self.n_agents > 1 else 0
        if a.shape != shape or not np.issubdtype(a.dtype, np.integer) or a.min() < low or a.max() >= n:
            size = f"{self.num_envs}" if self.n_agents == 1 else f"{self.num_envs} x {self.n_agents}"
            raise ValueError(f"actions must be {size} integers in {low}..{n - 1}, got {actions!r}")
        w = self.worlds
        w.step(a.astype(np.int64))
        obs = self._observe()
        if self.n_agents == 1:
            reward = w.rewards()
        else:
            each = np.stack([w.rewards(j) for j in range(self.n_agents)], axis=1)
            reward = each.sum(axis=1)
        terminated, truncated = w.terminated(), w.truncated(self.max_episode_steps)
        info = self._info(self._all)
        done = terminated | truncated
        if done.any():
            final_info = self._with_masks({k: v for k, v in info.items() if not k.startswith("_")}, done)
            if w.spec.win or w.spec.loss:  # how the games ended, as the world declares ([end] win, loss)
                final_info["outcome"] = w.outcomes()
                final_info["won"] = final_info["outcome"] == "win"
            ended = np.flatnonzero(done)
            w.reset(ended)
            # the others' observations read again, unchanged; the restarted worlds' history is their start
            final_obs, obs = obs, self._observe(ended)
            info = self._info(self._all)
            info.update(final_obs=final_obs, _final_obs=done, final_info=final_info, _final_info=done)
        if self.n_agents > 1:
            info.update(agent_reward=each, _agent_reward=self._all)
        return obs, reward, terminated, truncated, info

    def _observe(self, start: np.ndarray | None = None) -> Any:
        """Every agent's observation with its history (`start`: the worlds whose history starts now)."""
        w = self.worlds
        each = [h.step(w.observations(j)) if start is None else h.start(w.observations(j), start)
                for j, h in enumerate(self._histories)]
        return each[0] if self.n_agents == 1 else np.stack(each, axis=1)

    def _info(self, mask: np.ndarray) -> dict[str, Any]:
        w = self.worlds
        info: dict[str, Any] = {"t": w.steps.copy()}
        masks = [w.action_masks(j) for j in range(self.n_agents)]
        if masks[0] is not None:
            info["action_mask"] = masks[0] if self.n_agents == 1 else np.stack(masks, axis=1)
        for key, ids in self._flags.items() if self.n_agents > 1 else ():  # what a team's trainer reads
            held = w.holds(ids)
            if held is not None:
                info[key] = held
        return self._with_masks(info, mask)

    def script(self) -> np.ndarray | None:
        """bool [W, A] ([W, agents, A] for several) of the current state: the actions the spec's `[agents]
        script` names as the world's scripted choice (a trainer's --explore-scripted); None where undeclared."""
        held = self.worlds.holds(self.worlds.one._script_ids)
        if held is None:
            return None
        held = held.reshape(self.num_envs, self.n_agents, -1)
        return held[:, 0] if self.n_agents == 1 else held

    _with_masks = staticmethod(with_masks)

