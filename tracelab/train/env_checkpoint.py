"""Checkpoints of a `train --env` run, in the same place as GridWar's (RUN/checkpoint/checkpoint.pt,
checkpoint.py) under their own format: the config, the env as the user named it, the network and Adam,
the replay buffer, the generators, the step and the logging state, and the games in progress.

An env's worlds are not pickled (a declared world's engine does not move between processes, and
gymnasium's envs are not made to be). Each world is wrapped in EpisodeLog, which keeps the state of the
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
from tracelab.train.checkpoint import (_as_tensors, _checkpoint_file, _in_range, _rng_state, check_buffer_rows,
                                       checkpoint_config, checkpoint_path, learner_schema,
                                       restore_progress)
from tracelab.train.config import config_schema
from tracelab.train.torch_files import Tensor, load_tensors
from tracelab.validation import Const, IntRange, ListOf, MapOf, Mismatch, Nullable, OneOf, Tuple, check

ENV_FORMAT = "tracelab-dqn-env-checkpoint/1"


class EpisodeLog(gym.Wrapper):
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


def save_env_checkpoint(tr: Any, run_dir: Path) -> Path:
    """Write an EnvTrainer's whole state (its worlds made with EpisodeLog); returns the file."""
    path = checkpoint_path(run_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    logs = tr.env.envs
    actions = np.zeros((tr.worlds, max(len(e.actions) for e in logs)), np.int64)
    for k, e in enumerate(logs):
        actions[k, :len(e.actions)] = e.actions
    state = {
        "format": ENV_FORMAT, "config": tr.cfg.to_dict(), "env": tr.source.to_json(), "run": str(run_dir),
        "step": tr.step, "next_episode": tr.next_episode, "update_credit": tr.update_credit,
        "synced_block": tr.synced_block, "eval_round": tr.eval_round, "returns_since_log": list(tr.returns_since_log),
        "last_loss": tr.last_loss, "logged_step": tr.logged_step, "eval_step": tr.eval_step,
        "best_eval": tr.best_eval, "best_weights": {"shared": tr.best_weights} if tr.best_weights else {},
        "learner": tr.learner_kind, "learners": {"shared": tr.learner.state()},
        "rng": tr.rng.bit_generator.state, "torch_rng": tr.torch_gen.get_state(),
        "games": {"ep_len": tr.ep_len, "ep_return": tr.ep_return, "ep_id": tr.ep_id, "actions": actions,
                  "obs": tr.encoder(tr.obs)},
        "env_rng": {"start": [e.start_state for e in logs], "now": [e.unwrapped.np_random.bit_generator.state
                                                                    for e in logs]},
    }
    tmp = path.with_suffix(".tmp")
    torch.save(_as_tensors(state), tmp)
    tmp.replace(path)
    return path


def checkpoint_env(run: str | Path, max_bytes: int) -> tuple[dict[str, Any], EnvSource]:
    """(the raw checkpoint of an --env run, the env it names), its format checked; FileRefused otherwise."""
    f = _checkpoint_file(Path(run))
    state = load_tensors(f, max_bytes)
    try:
        check(state, {"format": Const(ENV_FORMAT), "config": config_schema(),
                      "env": {"name": str, "kwargs": MapOf(object)}, "learner": OneOf("fused", "readable")})
    except Mismatch as e:
        raise FileRefused(f"{f}: not a tracelab --env training checkpoint ({e})") from None
    return state, env_source_from_json(state["env"], str(f))


def load_env_checkpoint(run: str | Path, given: EnvSource | None, max_bytes: int) -> dict[str, Any]:
    """The checkpoint of a `train --env` run, checked against the env the user names (`given`; None: a
    UserError saying how to name it) and the shapes that env and the checkpoint's config imply."""
    from tracelab.train.env_source import ObservationEncoder, action_count
    from tracelab.train.qnet import NetSpec
    f = checkpoint_path(Path(run))
    state, recorded = checkpoint_env(run, max_bytes)
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
    finally:
        probe.close()
    net = NetSpec(encoder.size, cfg.hidden_sizes, n_actions, cfg.dueling)
    learner, best = learner_schema(cfg, net)
    w = cfg.envs
    rngs = Tuple(*[_rng_state()] * w)  # one per world
    try:
        check(state, {
            "run": str, "step": IntRange(0), "next_episode": IntRange(0), "update_credit": float,
            "synced_block": IntRange(0), "eval_round": IntRange(0), "returns_since_log": ListOf(float),
            "last_loss": Nullable(float), "logged_step": IntRange(-1), "eval_step": IntRange(-1),
            "best_eval": Nullable(Tuple(float, IntRange(0))), **best, "learners": {"shared": learner},
            "rng": _rng_state(), "torch_rng": Tensor(torch.uint8, (torch.Generator().get_state().numel(),)),
            "games": {"ep_len": Tensor(torch.int64, (w,)), "ep_return": Tensor(torch.float64, (w,)),
                      "ep_id": Tensor(torch.int64, (w,)), "actions": Tensor(torch.int64, (w, None)),
                      "obs": Tensor(torch.float32, (w, encoder.size))},
            "env_rng": {"start": rngs, "now": rngs}})
        check_buffer_rows(state["learners"]["shared"]["buffer"], n_actions, "learners.shared.buffer")
        games = state["games"]
        _in_range(games["ep_len"], 0, games["actions"].shape[1], "games.ep_len")
        _in_range(games["actions"], 0, n_actions - 1, "games.actions")
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


def restore_env_trainer(tr: Any, state: dict[str, Any]) -> None:
    """Put a freshly built EnvTrainer (same config and env) into the checkpoint's state: its learner,
    counters and generators, and its worlds replayed to where they were."""
    if tr.learner_kind != state["learner"]:
        raise ValueError(f"the checkpoint holds the {state['learner']} learner's state; this trainer runs the "
                         f"{tr.learner_kind} one")
    tr.learner.load_state(state["learners"]["shared"])
    restore_progress(tr, state)
    tr.best_weights = dict(state["best_weights"].get("shared", {}))
    tr.write_best_policy()  # a resumed run into a new directory keeps it too
    g = state["games"]
    tr.ep_len[...], tr.ep_return[...], tr.ep_id[...] = g["ep_len"], g["ep_return"], g["ep_id"]
    observations, infos = [], []
    for k, env in enumerate(tr.env.envs):
        obs, info = env.replay(state["env_rng"]["start"][k], g["actions"][k, :g["ep_len"][k]].tolist())
        env.unwrapped.np_random.bit_generator.state = state["env_rng"]["now"][k]
        observations.append(obs)
        infos.append(info)
    space = tr.env.single_observation_space
    obs = concatenate(space, observations, create_empty_array(space, tr.worlds))
    if not np.array_equal(tr.encoder(obs), g["obs"]):
        raise ValueError("replaying the checkpoint's games did not reproduce their observations: another env "
                         "(or version of it) than the one it was written with, or an edited file")
    tr.obs = obs
    tr.info = {"action_mask": np.stack([i["action_mask"] for i in infos])} if "action_mask" in infos[0] else {}
    tr._begun = []  # the episodes begun at the trainer's build are not the checkpoint's
