"""What a training checkpoint's parts hold, as validation schemas with their types and shapes (the trainer's
parts: EnvTrainer.state; env_checkpoint.py checks a loaded file against them before anything uses it), and
the consistency checks a schema cannot say (lengths that follow other keys, values the code indexes with)."""
from __future__ import annotations

from typing import Any

import torch

from tracelab.train.config import TrainConfig
from tracelab.train.torch_files import Tensor
from tracelab.validation import Const, ExactKeys, IntRange, ListOf, MapOf, Mismatch, Nullable, OptionalKey, Tuple


def rng_state_schema() -> dict[str, Any]:
    """A numpy PCG64 generator's state (Generators.state's `rng`)."""
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


def parts_schema() -> dict[str, Any]:
    """The keys the trainer's parts write (EnvTrainer.state): the step and evaluation rounds,
    UpdateSchedule, EpisodeLog's counters, MetricLog, BestPolicy's figures, Generators."""
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
    NetSpec, or `network`'s custom module: Python API) under cfg's learner, buffer and batch."""
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
    else:
        learner = {"online": weights, "target": weights, "adam": adam, "updates": IntRange(0), "buffer": buffer,
                   "loss_sum": float, "loss_n": IntRange(0), "last_q": Nullable(Tensor(torch.float32, (cfg.batch, a)))}
    return learner, {"best_weights": MapOf(weights)}


def check_best(state: dict[str, Any], groups: set[str]) -> None:
    """The best evaluation's networks: one per network name when there was an evaluation, none before."""
    best = state["best_weights"]
    if (state["best_eval"] is None) != (not best) or (best and set(best) != groups):
        raise Mismatch("best_weights", f"one network per network name ({', '.join(sorted(groups))}) with best_eval, "
                            f"none without", best)


def check_buffer_rows(buf: dict[str, Any], n_actions: int, where: str) -> None:
    """A replay buffer's state: as many rows as its size says, actions the networks have (they index)."""
    for key in ("obs", "next_obs", "action", "reward", "discount", "next_allowed"):
        if key in buf and len(buf[key]) != buf["size"]:
            raise Mismatch(f"{where}.{key}", f"{buf['size']} rows (its size)", buf[key])
    in_range(buf["action"], 0, n_actions - 1, f"{where}.action")


def in_range(values: torch.Tensor, lo: int, hi: int, where: str) -> None:
    """Every value within [lo, hi]: they index arrays that do not check bounds."""
    if values.numel() and (int(values.min()) < lo or int(values.max()) > hi):
        raise Mismatch(where, f"values from {lo} to {hi}", values)
