"""Checkpoints of a training run: `RUN/checkpoint/checkpoint.pt` (the latest; written to a temporary name,
then renamed) holds the config, the scenario, the networks, Adam, the replay buffers, the states of the
three generators (exploration and sampling, torch, the opponent's), the step, and the games in progress.
`learner` says which learner wrote the networks' state (fused or readable; absent: fused, written before
there were two), and a resume takes that one whatever `--learner auto` would pick today.

The trainer's state is its parts' (Trainer.state: each part saves and loads itself, under the keys
checkpoints have always had). The simulators' worlds are not pickled: the checkpoint keeps the actions
played since each episode began and a restore replays them (game_record.py).

A checkpoint may come from a stranger (a run attached to a bug report), so it holds nothing but tensors
and plain values (format 2: numpy arrays are saved as tensors), loads with torch's weights_only
unpickler, and is checked against the shapes its own config implies before anything uses it. Format 1
held numpy arrays, which only a full unpickler (one that runs whatever the file names) loads: it is
refused, with what the user can do instead."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.engine.safe_files import FileRefused
from tracelab.store import layout
from tracelab.game.scenario import NOTHING, Scenario, scenario_from_dict
from tracelab.train.memory import Limit, MemoryLimitExceeded, check_training_memory, memory_limit
from tracelab.train.network import to_state_dict
from tracelab.validation import (Const, ExactKeys, IntRange, ListOf, MapOf, Mismatch, Nullable, OneOf,
                                 OptionalKey, Tuple, check)
from tracelab.train.config import TrainConfig, config_schema
from tracelab.train.torch_files import CodeInFile, Tensor, load_tensors

# deferred: tracelab.train.run_networks loads the game's numba modules, which an env's checkpoint does not need
# (RuleSim's checkpoints only)

CHECKPOINT_DIR, CHECKPOINT_FILE = "checkpoint", "checkpoint.pt"
FORMAT = "tracelab-dqn-checkpoint/2"
OLD_FORMATS = (b"tracelab-dqn-checkpoint/1",)  # held numpy arrays: loadable only by running the pickle
NUMPY_SECTIONS = ("games", "pending")  # saved from numpy arrays, given back as numpy (and each "buffer")


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


def save_checkpoint(tr: Any, run_dir: Path) -> Path:
    """Write the trainer's whole state (its parts', Trainer.state) with its config and scenario; returns
    the file."""
    state = {"format": FORMAT, "config": tr.cfg.to_dict(), "scenario_toml": tr.scenario.to_toml(),
             "run": str(run_dir), **tr.state()}
    return write_checkpoint(run_dir, state)


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


def load_checkpoint(run: str | Path, limit: Limit | None = None, network: Any = None) -> dict[str, Any]:
    """The checkpoint of a training run directory, checked: its config and scenario are valid, its training
    fits `limit` (default: the memory limit, tracelab.train.memory; also the largest file read) and every
    array has the shape and type they imply. `network`: the factory of the custom module a run trained (Python API,
    Trainer's `network`), whose state dict says what the checkpoint's networks must hold."""
    run, limit = Path(run), memory_limit() if limit is None else limit
    f = checkpoint_file(run)
    try:
        state = load_tensors(f, limit.bytes)
    except CodeInFile as e:
        said = f"{f}: a checkpoint of an older tracelab (format 1, holding numpy objects that only a loader " \
               f"that runs code could read); refused" if any(mark in e.pickled for mark in OLD_FORMATS) else str(e)
        raise refusal_with_a_way_on(run, said) from None
    try:
        check(state, {"format": Const(FORMAT), "config": config_schema(), "scenario_toml": str,
                      "learner": OptionalKey(OneOf("fused", "readable")), "custom_network": OptionalKey(bool)})
    except Mismatch as e:
        raise FileRefused(f"{f}: not a tracelab training checkpoint of format 2 ({e})") from None
    try:
        cfg = checkpoint_config(state)
    except ValueError as e:  # a value out of range
        raise FileRefused(f"{f}: config: {e}") from None
    try:
        scenario = checkpoint_scenario(state)
    except tomllib.TOMLDecodeError as e:
        raise FileRefused(f"{f}: scenario_toml: not valid TOML: {e}") from None
    except ValueError as e:  # ScenarioError: names the field
        raise FileRefused(f"{f}: {e}") from None
    try:  # the config sizes the schema below (config.envs = 1e9: a billion worlds' games)
        check_training_memory(cfg, scenario, limit)
    except MemoryLimitExceeded as e:
        raise FileRefused(f"{f}: config: {e}") from None
    if state.get("custom_network") and network is None:
        raise FileRefused(f"{f}: the run trained a custom torch module (Python API): resume it in Python, "
                          f"load_checkpoint(run, network=...) and Trainer(..., network=...) with the same module")
    try:
        check(state, _state_schema(cfg, scenario, network))
        _check_consistency(state, cfg, scenario)
    except Mismatch as e:
        raise FileRefused(f"{f}: {e}") from None
    if "best_rows" in state:  # written before the readable learner: the fused layout's rows
        from tracelab.train.run_networks import training_net
        net = training_net(cfg, scenario)
        state["best_weights"] = {name: to_state_dict(row, net) for name, row in state.pop("best_rows").items()}
    for section in NUMPY_SECTIONS:
        state[section] = {k: v.numpy() for k, v in state[section].items()}
    for learner in state["learners"].values():
        learner["buffer"] = {k: v.numpy() if isinstance(v, torch.Tensor) else v
                             for k, v in learner["buffer"].items()}
    return state


def rng_state_schema() -> dict[str, Any]:
    return {"bit_generator": Const("PCG64"), "state": {"state": IntRange(0), "inc": IntRange(0)},
            "has_uint32": IntRange(0, 1), "uinteger": IntRange(0)}


def _network_tensors(net: Any, network: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the online network's state dict, Adam's moments by parameter name) as schemas: from the
    architecture `net` (a NetSpec) describes, computed (a stranger's config builds nothing before it is
    checked), or from a custom module's own state dict."""
    if network is None:
        shapes = {k: (torch.float32, s) for k, s in net.state_dict_shapes().items()}
        params = set(shapes)
    else:
        module = network(net.inputs, net.actions)
        shapes = {k: (v.dtype, tuple(v.shape)) for k, v in module.state_dict().items()}
        params = {k for k, _ in module.named_parameters()}
    weights = ExactKeys({k: Tensor(dtype, s) for k, (dtype, s) in shapes.items()})
    adam = ExactKeys({k: OptionalKey({"step": float, "exp_avg": Tensor(dtype, s), "exp_avg_sq": Tensor(dtype, s)})
                      for k, (dtype, s) in shapes.items() if k in params})
    return weights, adam


def _state_schema(cfg: TrainConfig, scenario: Scenario, network: Any = None) -> dict[str, Any]:
    """Every key of a format-2 checkpoint of this config and scenario, with its type and shape (cfg.learner:
    the learner the checkpoint names)."""
    from tracelab.train.run_networks import network_groups, training_net
    net = training_net(cfg, scenario)
    w, n, d = cfg.envs, scenario.agents_per_team, net.inputs
    learner, best = learner_schema(cfg, net, network)
    return {
        **parts_schema(), **best,
        "learners": {name: learner for name in network_groups(scenario, cfg.split_networks)},
        "env_rng": rng_state_schema(),
        "games": {"history": Tensor(torch.int16, (w, scenario.max_steps, 2, n)), **episode_games_schema(w),
                  "obs": Tensor(torch.float32, (w, d))},
        "pending": {"obs": Tensor(torch.float32, (w, n, d)), "action": Tensor(torch.int64, (w, n)),
                    "reward": Tensor(torch.float64, (w, n)), "discount": Tensor(torch.float64, (w, n)),
                    "open": Tensor(torch.bool, (w, n))},
    }


def parts_schema() -> dict[str, Any]:
    """The keys both trainers' parts write (GridWar's Trainer.state, EnvTrainer.state): the step and
    evaluation rounds, UpdateSchedule, EpisodeLog's counters, MetricLog, BestPolicy's figures, Generators."""
    return {
        "run": str, "step": IntRange(0), "next_episode": IntRange(0), "update_credit": float,
        "synced_block": IntRange(0), "eval_round": IntRange(0), "returns_since_log": ListOf(float),
        "last_loss": Nullable(float), "logged_step": IntRange(-1), "eval_step": IntRange(-1),
        "best_eval": Nullable(Tuple(float, IntRange(0))),
        "rng": rng_state_schema(), "torch_rng": Tensor(torch.uint8, (torch.Generator().get_state().numel(),)),
    }


def episode_games_schema(worlds: int) -> dict[str, Any]:
    """EpisodeLog's arrays under `games`."""
    return {"ep_len": Tensor(torch.int64, (worlds,)), "ep_return": Tensor(torch.float64, (worlds,)),
            "ep_id": Tensor(torch.int64, (worlds,)), "ep_start": Tensor(torch.int64, (worlds,))}


def learner_schema(cfg: TrainConfig, net: Any, network: Any = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(one learner's state, the best evaluation's networks) as schemas for the architecture `net` (a
    NetSpec) under cfg's learner, buffer and batch: GridWar's checkpoints and train --env's
    (env_checkpoint.py) check their networks with it."""
    a, d = net.actions, net.inputs
    buffer = {"size": IntRange(0, cfg.buffer), "pos": IntRange(0, cfg.buffer - 1),
              "obs": Tensor(torch.float32, (None, d)), "next_obs": Tensor(torch.float32, (None, d)),
              "action": Tensor(torch.int64, (None,)),
              "reward": Tensor(torch.float32, (None, len(net.terms)) if net.terms else (None,)),
              "discount": Tensor(torch.float32, (None,))}
    if cfg.mask:
        buffer["next_allowed"] = Tensor(torch.bool, (None, a))
    weights, adam = _network_tensors(net, network)
    if cfg.learner == "fused":
        p = net.n_params
        learner = {"params": Tensor(torch.float32, (2, p)), "adam_m": Tensor(torch.float32, (p,)),
                   "adam_v": Tensor(torch.float32, (p,)), "adam_step": IntRange(0), "updates": IntRange(0),
                   "buffer": buffer, "loss_sum": float, "loss_n": IntRange(0),
                   "last_q": Nullable(Tensor(torch.float32, (2, cfg.batch, a)))}
        # the best evaluation's networks as state dicts, or (written before) as the fused layout's rows
        best = {"best_weights": OptionalKey(MapOf(weights)),
                "best_rows": OptionalKey(MapOf(Tensor(torch.float32, (p,))))}
    else:
        learner = {"online": weights, "target": weights, "adam": adam, "updates": IntRange(0), "buffer": buffer,
                   "loss_sum": float, "loss_n": IntRange(0), "last_q": Nullable(Tensor(torch.float32, (cfg.batch, a)))}
        best = {"best_weights": MapOf(weights)}
    return learner, best


def _check_consistency(state: dict[str, Any], cfg: TrainConfig, scenario: Scenario) -> None:
    """What a schema cannot say: lengths that follow other keys, and the values the code indexes with (the
    replayed actions reach compiled kernels, which do not check bounds)."""
    n_actions = scenario.n_actions
    for name, learner in state["learners"].items():
        check_buffer_rows(learner["buffer"], n_actions, f"learners.{name}.buffer")
    in_range(state["pending"]["action"], 0, n_actions - 1, "pending.action")
    games = state["games"]
    in_range(games["ep_len"], 0, scenario.max_steps, "games.ep_len")
    history = games["history"]
    played = torch.arange(history.shape[1])[None, :] < games["ep_len"][:, None]  # [W, steps]
    in_range(history[played], 0, NOTHING, "games.history")
    check_best(state, set(state["learners"]))
    for key in ("rng", "env_rng"):
        try:
            np.random.PCG64().state = state[key]
        except (ValueError, TypeError, OverflowError) as e:
            raise Mismatch(key, f"a numpy PCG64 generator state (numpy: {e})", state[key]) from None


def check_best(state: dict[str, Any], groups: set[str]) -> None:
    """The best evaluation's networks: one per network name when there was an evaluation, none before."""
    key = "best_weights" if "best_weights" in state else "best_rows"
    if key not in state:
        raise Mismatch("best_weights", "the best evaluation's networks", missing=True)
    best = state[key]
    if (state["best_eval"] is None) != (not best) or (best and set(best) != groups):
        raise Mismatch(key, f"one network per network name ({', '.join(sorted(groups))}) with best_eval, "
                            f"none without", best)


def check_buffer_rows(buf: dict[str, Any], n_actions: int, where: str) -> None:
    """A replay buffer's state: as many rows as its size says, actions the networks have (they index)."""
    for key in ("obs", "next_obs", "action", "reward", "discount", "next_allowed"):
        if key in buf and len(buf[key]) != buf["size"]:
            raise Mismatch(f"{where}.{key}", f"{buf['size']} rows (its size)", buf[key])
    in_range(buf["action"], 0, n_actions - 1, f"{where}.action")


def in_range(values: torch.Tensor, lo: int, hi: int, where: str) -> None:
    if values.numel() and (int(values.min()) < lo or int(values.max()) > hi):
        raise Mismatch(where, f"values from {lo} to {hi}", values)


def checkpoint_config(state: dict[str, Any]) -> TrainConfig:
    """The run's config, with the learner that wrote the checkpoint (fused when it does not say)."""
    return TrainConfig.from_dict({**state["config"], "learner": state.get("learner", "fused")})


def checkpoint_scenario(state: dict[str, Any]) -> Scenario:
    """The scenario the checkpointed run trained on (as it was then)."""
    return scenario_from_dict(tomllib.loads(state["scenario_toml"]), source="checkpoint scenario")


def restore(tr: Any, state: dict[str, Any]) -> None:
    """Put a freshly built Trainer (same config) into the checkpoint's state."""
    tr.load_state(state)
