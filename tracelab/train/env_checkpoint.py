"""Checkpoints of a `train --env` run, in the same place as GridWar's (RUN/checkpoint/checkpoint.pt,
checkpoint.py) under their own format: the config, the env as the user named it, the network and Adam,
the replay buffer, the generators, the step and the logging state, and the games in progress.

The trainer's state is its parts' (EnvTrainer.state, as GridWar's Trainer.state). An env's worlds are not
pickled (a declared world's engine does not move between processes, and gymnasium's envs are not made to
be). Each world is wrapped in ReplayableEnv, which keeps the state of the
env's np_random when its episode began and the actions since; a restore sets that state, resets and
replays the actions. That brings a world back exactly when all of its randomness is its np_random
(gymnasium's contract, and how every declared world draws); the observation each replay ends in is
checked against the saved one.

A checkpoint may come from a stranger: it holds only tensors and plain values, loads with torch's
weights_only unpickler and is checked against the shapes its config and env imply. It names its env, but
a resume makes the env the user names (`--env`, checked equal to the checkpoint's): a file never decides
which spec file tracelab reads."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.utils import seeding
from gymnasium.vector.utils import concatenate, create_empty_array

from tracelab.engine.safe_files import FileRefused
from tracelab.envs.declared.env_source import EnvSource, check_same_env, env_source_from_json
from tracelab.errors import UserError
from tracelab.train.checkpoint import (check_best, check_buffer_rows, checkpoint_config,
                                       checkpoint_file, checkpoint_path, episode_games_schema, in_range,
                                       learner_schema, parts_schema, rng_state_schema, write_checkpoint)
from tracelab.train.config import config_schema
from tracelab.train.env_source import ObservationEncoder, action_count
from tracelab.train.memory import (Limit, MemoryLimitExceeded, check_estimate, env_training_estimate,
                                   env_world_bytes)
from tracelab.train.torch_files import Tensor, load_tensors
from tracelab.validation import Const, MapOf, Mismatch, OneOf, Tuple, check

ENV_FORMAT = "tracelab-dqn-env-checkpoint/1"


class ReplayableEnv(gym.Wrapper):
    """An env that remembers how its episode began (its np_random's state before the reset's draws) and
    the actions since, and can replay them into itself."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.start_state: dict[str, Any] | None = None
        self.actions: list[int] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        rng = seeding.np_random(seed)[0] if seed is not None else self.env.unwrapped.np_random
        self.start_state, self.actions = rng.bit_generator.state, []
        return self.env.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        self.actions.append(int(action))
        return self.env.step(action)

    def replay(self, start_state: dict[str, Any], actions: list[int]) -> tuple[Any, dict[str, Any]]:
        """The episode that began in `start_state` and played `actions`, brought back; (its observation,
        its last info). ValueError when it ended before its last action (another env, or an edited file)."""
        rng = np.random.Generator(np.random.PCG64())
        rng.bit_generator.state = start_state
        self.env.unwrapped.np_random = rng
        obs, info = self.reset()
        self.start_state = start_state
        for k, action in enumerate(actions):
            obs, _, terminated, truncated, info = self.step(action)
            if (terminated or truncated) and k < len(actions) - 1:
                raise ValueError(f"the replayed episode ended after {k + 1} of its {len(actions)} actions")
        return obs, info


def worlds_state(envs: list[ReplayableEnv]) -> dict[str, Any]:
    """What replays the worlds (a checkpoint's `env_rng` and `games.actions`): each np_random's state at
    its episode's start and now, and the actions since the start [W, longest] (zero-padded)."""
    actions = np.zeros((len(envs), max((len(e.actions) for e in envs), default=0)), np.int64)
    for k, e in enumerate(envs):
        actions[k, :len(e.actions)] = e.actions
    return {"start": [e.start_state for e in envs], "now": [e.unwrapped.np_random.bit_generator.state for e in envs],
            "actions": actions}


def replay_worlds(vector_env: Any, actions: np.ndarray, lengths: np.ndarray,
                  env_rng: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """Bring each world of `vector_env` (ReplayableEnvs) back to its episode's first lengths[w] actions,
    its np_random to its saved state; (the batch's observations, its info). ValueError when an episode
    ends early."""
    observations, infos = [], []
    for k, env in enumerate(vector_env.envs):
        obs, info = env.replay(env_rng["start"][k], actions[k, :lengths[k]].tolist())
        env.unwrapped.np_random.bit_generator.state = env_rng["now"][k]
        observations.append(obs)
        infos.append(info)
    space = vector_env.single_observation_space
    obs = concatenate(space, observations, create_empty_array(space, len(observations)))
    return obs, {"action_mask": np.stack([i["action_mask"] for i in infos])} if "action_mask" in infos[0] else {}


def save_env_checkpoint(tr: Any, run_dir: Path) -> Path:
    """Write an EnvTrainer's whole state (its parts', EnvTrainer.state) with its config and env; returns
    the file."""
    state = {"format": ENV_FORMAT, "config": tr.cfg.to_dict(), "env": tr.source.to_json(), "run": str(run_dir),
             **tr.state()}
    return write_checkpoint(run_dir, state)


def checkpoint_env(run: str | Path, max_bytes: int) -> tuple[dict[str, Any], EnvSource]:
    """(the raw checkpoint of an --env run, the env it names), its format checked; FileRefused otherwise."""
    f = checkpoint_file(Path(run))
    state = load_tensors(f, max_bytes)
    try:
        check(state, {"format": Const(ENV_FORMAT), "config": config_schema(),
                      "env": {"name": str, "kwargs": MapOf(object)}, "learner": OneOf("fused", "readable")})
    except Mismatch as e:
        raise FileRefused(f"{f}: not a tracelab --env training checkpoint ({e})") from None
    return state, env_source_from_json(state["env"], str(f))


def load_env_checkpoint(run: str | Path, given: EnvSource | None, limit: Limit) -> dict[str, Any]:
    """The checkpoint of a `train --env` run, checked against the env the user names (`given`; None: a
    UserError saying how to name it) and the shapes that env and the checkpoint's config imply; a config
    whose training would not fit `limit` is refused before anything it sizes is built."""
    f = checkpoint_path(Path(run))
    state, recorded = checkpoint_env(run, limit.bytes)
    if given is None:
        raise UserError(f"{run} trained on an env: name it again to resume (tracelab reads no spec a run "
                        f"names by itself): tracelab train --resume {run} --env {recorded.describe()}")
    check_same_env(recorded, given, str(run))
    try:
        cfg = checkpoint_config(state)
    except ValueError as e:
        raise FileRefused(f"{f}: config: {e}") from None
    probe = given.make()
    try:
        encoder = ObservationEncoder(probe.observation_space, given.name)
        n_actions = action_count(probe.action_space, given.name)
        spec = getattr(probe.unwrapped, "world_spec", None)
    finally:
        probe.close()
    try:
        net = cfg.network(encoder.size, n_actions, spec.reward_terms if spec is not None else ())
    except ValueError as e:
        raise FileRefused(f"{f}: config: {e}") from None
    try:  # config.envs sizes the schema below: a stranger's 1e9 is refused here, not by the OOM killer
        check_estimate(env_training_estimate(cfg, net, env_world_bytes(spec)), limit)
    except MemoryLimitExceeded as e:
        raise FileRefused(f"{f}: config: {e}") from None
    learner, best = learner_schema(cfg, net)
    w = cfg.envs
    state.pop("best_rows", None)  # GridWar's old layout of the best networks: never an --env run's
    rngs = Tuple(*[rng_state_schema()] * w)  # one per world
    try:
        check(state, {
            **parts_schema(), **best, "learners": {"shared": learner},
            "games": {**episode_games_schema(w), "actions": Tensor(torch.int64, (w, None)),
                      "obs": Tensor(torch.float32, (w, encoder.size))},
            "env_rng": {"start": rngs, "now": rngs}})
        check_buffer_rows(state["learners"]["shared"]["buffer"], n_actions, "learners.shared.buffer")
        check_best(state, {"shared"})
        games = state["games"]
        in_range(games["ep_len"], 0, games["actions"].shape[1], "games.ep_len")
        in_range(games["actions"], 0, n_actions - 1, "games.actions")
        for where, value in [("rng", state["rng"]), *((f"env_rng.{k}", s) for k in ("start", "now")
                                                      for s in state["env_rng"][k])]:
            try:
                np.random.PCG64().state = value
            except (ValueError, TypeError, OverflowError) as e:
                raise Mismatch(where, f"a numpy PCG64 generator state (numpy: {e})", value) from None
    except Mismatch as e:
        raise FileRefused(f"{f}: {e}") from None
    state["games"] = {k: v.numpy() for k, v in state["games"].items()}
    buf = state["learners"]["shared"]["buffer"]
    state["learners"]["shared"]["buffer"] = {k: v.numpy() if isinstance(v, torch.Tensor) else v
                                             for k, v in buf.items()}
    return state
