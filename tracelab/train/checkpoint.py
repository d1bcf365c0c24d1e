"""Checkpoints of a training run: `RUN/checkpoint/checkpoint.pt` (the latest; written to a temporary name,
then renamed) holds the config, the scenario, the networks, Adam, the replay buffers, the states of the
three generators (exploration and sampling, torch, the opponent's), the step, and the games in progress.

The simulators' worlds are not pickled: a rule engine's state is not meant to move between processes.
Instead the checkpoint keeps, per world, the actions both teams played since its episode began, and a
restore replays them into a fresh env: the game is deterministic given the actions, so the worlds come
back exactly (the observation they end in is checked against the saved one)."""
from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import torch

from tracelab.game.scenario import NOTHING, RED, Scenario, scenario_from_dict
from tracelab.train.config import TrainConfig

CHECKPOINT_DIR, CHECKPOINT_FILE = "checkpoint", "checkpoint.pt"
FORMAT = "tracelab-dqn-checkpoint/1"


def checkpoint_path(run_dir: Path) -> Path:
    return Path(run_dir) / CHECKPOINT_DIR / CHECKPOINT_FILE


def save_checkpoint(tr: Any, run_dir: Path) -> Path:
    """Write the trainer's whole state; returns the file."""
    path = checkpoint_path(run_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {
        "format": FORMAT, "config": tr.cfg.to_dict(), "scenario_toml": tr.scenario.to_toml(),
        "run": str(run_dir), "step": tr.step, "next_episode": tr.next_episode, "update_credit": tr.update_credit,
        "synced_block": tr.synced_block, "eval_round": tr.eval_round, "returns_since_log": list(tr.returns_since_log),
        "last_loss": tr.last_loss, "logged_step": tr.logged_step, "eval_step": tr.eval_step,
        "best_eval": tr.best_eval, "best_rows": tr.best_rows,
        "learners": {name: lr.state() for name, lr in tr.learners.items()},
        "rng": tr.rng.bit_generator.state, "torch_rng": tr.torch_gen.get_state(),
        "env_rng": tr.env.sim.rng.bit_generator.state,
        "games": {"history": tr.history.copy(), "ep_len": tr.ep_len.copy(), "ep_return": tr.ep_return.copy(),
                  "ep_id": tr.ep_id.copy(), "ep_start": tr.ep_start.copy(), "obs": tr.obs.copy()},
        "pending": tr.pending.state(),
    }
    tmp = path.with_suffix(".tmp")
    torch.save(state, tmp)
    tmp.replace(path)
    return path


def load_checkpoint(run: str | Path) -> dict[str, Any]:
    """The checkpoint of a run directory (or a checkpoint file)."""
    p = Path(run)
    f = p if p.is_file() else checkpoint_path(p)
    if not f.exists():
        raise FileNotFoundError(f"no checkpoint at {str(f)!r} (a training run writes {CHECKPOINT_DIR}/"
                                f"{CHECKPOINT_FILE} into its run directory)")
    state = torch.load(f, map_location="cpu", weights_only=False)  # our own file: numpy arrays inside
    if state.get("format") != FORMAT:
        raise ValueError(f"{f}: not a tracelab training checkpoint (format {state.get('format')!r})")
    return state


def checkpoint_config(state: dict[str, Any]) -> TrainConfig:
    return TrainConfig.from_dict(state["config"])


def checkpoint_scenario(state: dict[str, Any]) -> Scenario:
    """The scenario the checkpointed run trained on (as it was then)."""
    return scenario_from_dict(tomllib.loads(state["scenario_toml"]), source="checkpoint scenario")


def restore(tr: Any, state: dict[str, Any]) -> None:
    """Put a freshly built Trainer (same config) into the checkpoint's state."""
    for name, lr in tr.learners.items():
        lr.load_state(state["learners"][name])
    tr.step, tr.next_episode = int(state["step"]), int(state["next_episode"])
    tr.update_credit, tr.synced_block = float(state["update_credit"]), int(state["synced_block"])
    tr.eval_round, tr.last_loss = int(state["eval_round"]), state["last_loss"]
    tr.logged_step, tr.eval_step = int(state["logged_step"]), int(state["eval_step"])
    tr.returns_since_log = list(state["returns_since_log"])
    best = state.get("best_eval")  # absent in checkpoints written before the best policy was kept
    tr.best_eval = None if best is None else (float(best[0]), int(best[1]))
    tr.best_rows = state.get("best_rows", {})
    tr.write_best_policy()  # a resumed run into a new directory keeps it too
    tr.rng.bit_generator.state = state["rng"]
    tr.torch_gen.set_state(state["torch_rng"])
    g = state["games"]
    tr.history[...] = g["history"]
    tr.ep_len[...] = g["ep_len"]
    tr.ep_return[...] = g["ep_return"]
    tr.ep_id[...] = g["ep_id"]
    tr.ep_start[...] = g["ep_start"]
    _replay_games(tr.env.sim, tr.history, tr.ep_len)
    tr.env.sim.rng.bit_generator.state = state["env_rng"]
    obs = tr.env.sim.observe(RED)
    if not np.array_equal(obs, g["obs"]):
        raise RuntimeError("restoring the checkpoint's games did not reproduce their observations: the "
                           "simulator is not the one the checkpoint was written with")
    tr.obs = obs
    tr.acting = tr.may_act()
    tr.pending.load_state(state["pending"])


def _replay_games(sim: Any, history: np.ndarray, ep_len: np.ndarray) -> None:
    """Bring every world to the state after its episode's first ep_len[w] steps. Worlds start their
    replay so that all end together; before that they idle (both teams do nothing), then are reset."""
    worlds, n = history.shape[0], history.shape[3]
    longest = int(ep_len.max()) if worlds else 0
    start = longest - ep_len
    sim.reset(worlds=np.ones(worlds, bool))
    idle = np.full((worlds, n), NOTHING, np.int64)
    for k in range(longest):
        begin = start == k
        if begin.any():
            sim.reset(worlds=begin)
        k_w = k - start
        playing = k_w >= 0
        red, blue = idle.copy(), idle.copy()
        idx = np.flatnonzero(playing)
        red[idx] = history[idx, k_w[idx], 0]
        blue[idx] = history[idx, k_w[idx], 1]
        sim.step(red, blue)
    if (ep_len == 0).any():
        sim.reset(worlds=ep_len == 0)
