"""Training checkpoints: RUN/checkpoint/checkpoint.pt (the latest; written new under a temporary name, then
renamed in) holds the config, the env as the user named it, the network and Adam, the replay buffer, the
generators, the step and the logging state, and the worlds' actions. `learner` says which learner wrote
the networks' state (fused or readable), and a resume takes that one whatever `--learner auto` would pick.

The trainer's state is its parts' (EnvTrainer.state; their schemas: checkpoint_schema.py). An env's
worlds are not pickled (a declared world's engine does not move between processes, and gymnasium's envs
are not made to be): the training's vector env (a declared world's DeclaredVectorEnv, or gymnasium's
SyncVectorEnv) was reset once with the run's env seed, and ActionLog keeps every action its worlds took
since; a restore resets a new vector env with that seed and steps it through them again. That brings the
worlds back exactly when all of their randomness comes from the seed (gymnasium's contract, and how every
declared world draws), whatever buffering of random numbers the vector env does; the observations the
replay ends in are checked against the saved ones. The log costs 8 bytes a training step; the replay runs
the env alone (no network), as many steps as the run has trained.

A checkpoint may come from a stranger: it holds only tensors and plain values, loads with torch's
weights_only unpickler and is checked against the shapes its config and env imply. It names its env, but
a resume makes the env the user names (`--env`, checked equal to the checkpoint's): a file never decides
which spec file tracelab reads. Checkpoints an earlier trainer of a world wrote (the war game's RuleSim
trainer) are refused in one line its registration gives (world_extras.retired_checkpoint), saying how to go on."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.engine.safe_files import FileRefused
from tracelab.envs.declared.env_source import EnvSource, check_same_env, env_source_from_json
from tracelab.errors import UserError
from tracelab.store import layout
from tracelab.train.checkpoint_schema import (check_best, check_buffer_rows, episode_games_schema, in_range,
                                              learner_schema, parts_schema)
from tracelab.train.config import TrainConfig, config_schema
from tracelab.train.env_source import probe_env
from tracelab.train.memory import (Limit, MemoryLimitExceeded, check_estimate, env_training_estimate,
                                   env_world_bytes)
from tracelab.train.torch_files import CodeInFile, Tensor, load_tensors
from tracelab.validation import Const, IntRange, MapOf, Mismatch, OneOf, OptionalKey, check
from tracelab.world_extras import retired_checkpoint

ENV_FORMAT = "tracelab-dqn-env-checkpoint/2"
# the first format kept each world's generator state and its episode's actions (per-world replay in
# gymnasium's SyncVectorEnv); the batched declared env has no per-world generator state to set
OLD_FORMATS = ("tracelab-dqn-env-checkpoint/1",)
CHECKPOINT_DIR, CHECKPOINT_FILE = "checkpoint", "checkpoint.pt"


def checkpoint_path(run_dir: Path) -> Path:
    return Path(run_dir) / CHECKPOINT_DIR / CHECKPOINT_FILE


def as_tensors(value: Any) -> Any:
    """Our own state with numpy arrays as tensors and numpy scalars as Python numbers: what weights_only
    loads."""
    if isinstance(value, dict):
        return {k: as_tensors(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(as_tensors(v) for v in value)
    if isinstance(value, np.ndarray):
        return torch.from_numpy(np.array(value))  # a copy: the trainer's arrays go on changing
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_checkpoint(run_dir: Path, state: dict[str, Any]) -> Path:
    """RUN/checkpoint/checkpoint.pt, through the store's path resolver (as parts and meta.json are
    written): created new under a temp name and renamed in, never through a link; returns the file."""
    layout.make_run_dirs(run_dir, CHECKPOINT_DIR)
    path = layout.run_path(run_dir, CHECKPOINT_DIR, CHECKPOINT_FILE)
    with layout.new_file(path) as f:
        torch.save(as_tensors(state), f)
    return path


def checkpoint_file(run: Path) -> Path:
    """RUN/checkpoint/checkpoint.pt of a run directory, refusing anything else before it is opened."""
    if not run.is_dir():
        raise FileRefused(f"{run}: not a training run's directory (one holding {CHECKPOINT_DIR}/"
                          f"{CHECKPOINT_FILE}); refused")
    folder = run / CHECKPOINT_DIR
    if folder.is_symlink():
        raise FileRefused(f"{folder}: is a symbolic link; refused")
    f = folder / CHECKPOINT_FILE
    if not folder.is_dir() or not (f.exists() or f.is_symlink()):
        raise FileNotFoundError(f"no checkpoint at {str(f)!r} (a training run writes {CHECKPOINT_DIR}/"
                                f"{CHECKPOINT_FILE} into its run directory)")
    return f


def refusal_with_a_way_on(run: Path, said: str, env: str = "") -> FileRefused:
    """A checkpoint refused for what it would run: say so, and what the user can do instead (use the
    run's policy, start a new run from its settings). `env`: what its policy needs named again (` --env
    ENV`: a train --env run's, whose env the refused file cannot tell)."""
    policy = run / "policy"
    if (policy / "policy.json").is_file():
        instead = f"its policy still plays: tracelab eval {policy}{env}, tracelab play --policy {policy}{env}; " \
                  f"to train on, start a new run with tracelab train (its settings: tracelab show {run})"
    else:
        instead = f"start a new run with tracelab train (its settings: tracelab show {run})"
    return FileRefused(f"{said}: {instead}")


def checkpoint_config(state: dict[str, Any]) -> TrainConfig:
    """The run's config, with the learner that wrote the checkpoint (fused when it does not say)."""
    return TrainConfig.from_dict({**state["config"], "learner": state.get("learner", "fused")})


class ActionLog:
    """Every action of the training worlds since their vector env's reset, one row [W] a pass."""

    def __init__(self, worlds: int) -> None:
        self.rows = np.zeros((1024, worlds), np.int64)
        self.n = 0

    def add(self, actions: np.ndarray) -> None:
        if self.n == len(self.rows):  # doubling: amortised O(1) a pass
            self.rows = np.concatenate([self.rows, np.zeros_like(self.rows)])
        self.rows[self.n] = actions
        self.n += 1

    def array(self) -> np.ndarray:
        return self.rows[:self.n]

    def load(self, actions: np.ndarray) -> None:
        self.rows = np.array(actions, np.int64).reshape(-1, self.rows.shape[1])
        self.n = len(self.rows)
        if self.n == 0:
            self.rows = np.zeros((1024, self.rows.shape[1]), np.int64)


def replay_actions(vector_env: Any, seed: int, actions: np.ndarray) -> tuple[Any, dict[str, Any]]:
    """`vector_env` reset with `seed` and stepped through `actions` [passes, W]: (its observations, its
    last info), where the training that logged them was."""
    obs, info = vector_env.reset(seed=seed)
    for row in actions:
        obs, _, _, _, info = vector_env.step(row)
    return obs, info


def save_env_checkpoint(tr: Any, run_dir: Path) -> Path:
    """Write a trainer's whole state (its parts', EnvTrainer.state) with its config and env; returns the
    file."""
    state = {"format": ENV_FORMAT, "config": tr.cfg.to_dict(), "env": tr.source.to_json(), "run": str(run_dir),
             **tr.state()}
    return write_checkpoint(run_dir, state)


def checkpoint_env(run: str | Path, max_bytes: int) -> tuple[dict[str, Any], EnvSource]:
    """(the raw checkpoint of an --env run, the env it names), its format checked; FileRefused otherwise."""
    f = checkpoint_file(Path(run))
    try:
        state = load_tensors(f, max_bytes)
    except CodeInFile as e:  # a stranger's (or a damaged) file: the run's policy may still play
        said = retired_checkpoint(None, e.pickled, str(f)) or str(e)
        raise refusal_with_a_way_on(Path(run), said, " --env ENV") from None
    if state.get("format") in OLD_FORMATS:
        raise FileRefused(f"{f}: written by an earlier tracelab ({state['format']}), whose worlds this one "
                          f"cannot rebuild: resume it with that version, or train again from its policy's "
                          f"settings (RUN/policy/policy.json, \"trained\")")
    retired = retired_checkpoint(state, b"", str(f))  # an earlier trainer's of a world (its registration's)
    if retired:
        raise FileRefused(retired)
    try:
        check(state, {"format": Const(ENV_FORMAT), "config": config_schema(),
                      "env": {"name": str, "kwargs": MapOf(object)}, "learner": OneOf("fused", "readable")})
    except Mismatch as e:
        raise FileRefused(f"{f}: not a tracelab --env training checkpoint ({e})") from None
    return state, env_source_from_json(state["env"], str(f))


def load_env_checkpoint(run: str | Path, given: EnvSource | None, limit: Limit,
                        network: Any = None) -> dict[str, Any]:
    """The checkpoint of a training run, checked against the env the user names (`given`; None: a
    UserError saying how to name it) and the shapes that env and the checkpoint's config imply; a config
    whose training would not fit `limit` is refused before anything it sizes is built. `network`: the
    factory of the custom module the run trained (Python API, EnvTrainer's `network`), whose state dict
    says what the checkpoint's networks hold."""
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
    encoder, n_actions, spec = probe_env(given)
    try:
        net = cfg.network(encoder.size, n_actions, spec.reward_terms if spec is not None else ())
    except ValueError as e:
        raise FileRefused(f"{f}: config: {e}") from None
    try:  # config.envs sizes the schema below: a stranger's 1e9 is refused here, not by the OOM killer
        check_estimate(env_training_estimate(cfg, net, env_world_bytes(spec)), limit)
    except MemoryLimitExceeded as e:
        raise FileRefused(f"{f}: config: {e}") from None
    if state.get("custom_network") and network is None:
        raise FileRefused(f"{f}: the run trained a custom torch module (Python API): resume it in Python, "
                          f"load_env_checkpoint(run, source, limit, network=...) and EnvTrainer(..., "
                          f"network=...) with the same module")
    learner, best = learner_schema(cfg, net, network)
    w = cfg.envs
    agents = getattr(encoder, "n_agents", 1)  # a team: a row per world and agent (env_trainer.py)
    team = {} if agents == 1 else {"pending": {
        "obs": Tensor(torch.float32, (w, agents, encoder.size)), "action": Tensor(torch.int64, (w, agents)),
        "reward": Tensor(torch.float64, (w, agents)), "discount": Tensor(torch.float64, (w, agents)),
        "open": Tensor(torch.bool, (w, agents))}}
    try:
        check(state, {
            **parts_schema(), **best, "learners": {"shared": learner}, "custom_network": OptionalKey(bool),
            "games": {**episode_games_schema(w), "obs": Tensor(torch.float32, (w * agents, encoder.size))},
            "env_seed": IntRange(0), "env_actions": Tensor(torch.int64, (None, w * agents)), **team})
        check_buffer_rows(state["learners"]["shared"]["buffer"], n_actions, "learners.shared.buffer")
        check_best(state, {"shared"})
        passes = state["step"] // w
        if state["env_actions"].shape[0] != passes:
            raise Mismatch("env_actions", f"{passes} rows (step {state['step']} of {w} worlds)",
                           f"{state['env_actions'].shape[0]} rows")
        in_range(state["env_actions"], 0 if agents == 1 else -1, n_actions - 1, "env_actions")  # -1: does nothing
        if team:
            in_range(state["pending"]["action"], 0, n_actions - 1, "pending.action")
        try:
            np.random.PCG64().state = state["rng"]
        except (ValueError, TypeError, OverflowError) as e:
            raise Mismatch("rng", f"a numpy PCG64 generator state (numpy: {e})", state["rng"]) from None
    except Mismatch as e:
        raise FileRefused(f"{f}: {e}") from None
    state["env_actions"] = state["env_actions"].numpy()
    state["games"] = {k: v.numpy() for k, v in state["games"].items()}
    if team:
        state["pending"] = {k: v.numpy() for k, v in state["pending"].items()}
    buf = state["learners"]["shared"]["buffer"]
    state["learners"]["shared"]["buffer"] = {k: v.numpy() if isinstance(v, torch.Tensor) else v
                                             for k, v in buf.items()}
    return state
