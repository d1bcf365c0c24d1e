"""How much memory a training run or a loaded policy will take, estimated from its sizes before anything is
built, and the limit it must fit (half the machine's memory unless the user says otherwise): a --hidden,
--buffer or --envs, or a policy file's network, too big for the machine is refused at once with the flag
and the estimate, not after minutes of swapping or an out-of-memory kill.

The estimates are of the arrays that grow with each size (measured figures where the engine's state is
concerned), rounded up; they are meant to tell a run that fits from one off by orders of magnitude."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from tracelab.engine.grounding_limit import usable_memory
from tracelab.envs.declared.spec_size import env_bytes
from tracelab.train.qnet import NetSpec
from tracelab.train.replay import row_length

MACHINE_SHARE = 0.5  # the default limit: this share of the machine's physical memory
FLOAT = 4            # bytes of a float32
# a gymnasium env's world in train --env's vector env that is not declared in rules: a small Python object
# at least (a declared world's is estimated from its spec: spec_size.env_bytes)
GYM_WORLD_BYTES = 4 << 10
# per network parameter: online and target rows, the gradient, Adam's two moments and its work row, the
# copies of a checkpoint, the best policy and a saved policy
PARAM_COPIES = 12
# per minibatch row and hidden unit: the update's activations and their gradients, both networks
ACTIVATION_COPIES = 8


class MemoryLimitExceeded(ValueError):
    """A size whose estimated memory is over the limit; the message names it and the estimate, `flags` the
    flags with their values of the part that takes the most ("--buffer 100000000")."""

    def __init__(self, message: str, flags: str = "") -> None:
        super().__init__(message)
        self.flags = flags


@dataclass(frozen=True)
class Limit:
    bytes: int
    source: str  # how the limit was set, for the message

    def __str__(self) -> str:
        return f"{self.bytes:,} bytes ({_gib(self.bytes)}, {self.source})"


def memory_limit(max_bytes: int | None = None, flag: str | None = None) -> Limit:
    """The limit a run or a policy must fit: `max_bytes`, given with `flag`, or by default half the
    machine's memory (`flag`, if any, is named as the way to raise it)."""
    if max_bytes is not None:
        return Limit(max_bytes, f"set by {flag}" if flag else "given")
    total = usable_memory()
    raise_it = f"; {flag} raises it" if flag else ""
    return Limit(int(total * MACHINE_SHARE), f"half of this machine's {_gib(total)}{raise_it}")


def network_bytes(shape: NetSpec) -> int:
    """A network's parameters with every copy training keeps or writes."""
    return PARAM_COPIES * shape.n_params * FLOAT


def replay_bytes(capacity: int, shape: NetSpec, masked: bool) -> int:
    """A replay buffer (its float32 rows and action ids), twice: a checkpoint copies what it holds."""
    return 2 * capacity * (row_length(shape.inputs, shape.actions, masked, max(1, len(shape.terms))) * FLOAT + 8)


def minibatch_bytes(batch: int, shape: NetSpec, masked: bool) -> int:
    return batch * row_length(shape.inputs, shape.actions, masked, max(1, len(shape.terms))) * FLOAT


def activation_bytes(batch: int, shape: NetSpec) -> int:
    """The update's activations and their gradients (both networks' forward passes, every layer)."""
    return batch * (ACTIVATION_COPIES * sum(h + 1 for h in shape.hidden) + 4 * shape.actions) * FLOAT


def env_world_bytes(spec: Any) -> int:
    """One world of train --env's vector env: a world declared in rules (`spec`, its WorldSpec) from the atoms
    its spec names, any other env (None) a small Python object."""
    return env_bytes(spec.named_atoms) if spec is not None else GYM_WORLD_BYTES


def env_training_estimate(cfg: Any, shape: NetSpec, world_bytes: int) -> list[tuple[str, str, int]]:
    """(flags with their values, what they size, estimated bytes) of each part of a training run that grows
    with a setting: one network of `shape`, its env's worlds of `world_bytes` each (env_world_bytes)."""
    world = world_bytes + 2 * shape.inputs * FLOAT  # and its observation, current and next
    eval_worlds = min(cfg.eval_envs, cfg.eval_games)
    return [
        (f"--hidden {cfg.hidden}", f"a network of {shape.inputs:,} inputs x {shape.hidden_text()} hidden units x "
                                   f"{shape.actions:,} actions", network_bytes(shape)),
        (f"--hidden {cfg.hidden} and --batch-size {cfg.batch}", f"the update's activations ({cfg.batch:,} "
         f"transitions x {shape.hidden_text()} hidden units)", activation_bytes(cfg.batch, shape)),
        (f"--batch-size {cfg.batch}", f"minibatches of {cfg.batch:,} transitions",
         minibatch_bytes(cfg.batch, shape, cfg.mask)),
        (f"--buffer-size {cfg.buffer}", f"a replay buffer of {cfg.buffer:,} transitions",
         replay_bytes(cfg.buffer, shape, cfg.mask)),
        (f"--num-envs {cfg.envs}", f"{cfg.envs:,} training worlds", cfg.envs * world),
        (f"--eval-envs {cfg.eval_envs}", f"{eval_worlds:,} evaluation worlds", eval_worlds * world),
    ]


def _gib(n: int) -> str:
    return f"{n / (1 << 30):,.1f} GiB" if n >= 1 << 30 else f"{n / (1 << 20):,.1f} MiB"


def check_estimate(parts: list[tuple[str, str, int]], limit: Limit) -> int:
    """Refuse an estimate (env_training_estimate's parts) over `limit`, naming the setting that takes the
    most; returns the total."""
    total = sum(b for _, _, b in parts)
    if total > limit.bytes:
        flags, what, most = max(parts, key=lambda p: p[2])
        whole = "" if most > limit.bytes else f"; the run {total:,} bytes in all"
        raise MemoryLimitExceeded(f"{flags}: {what} would take an estimated {most:,} bytes ({_gib(most)}"
                                  f"{whole}), over the limit of {limit}", flags)
    return total


def check_policy_memory(shape: NetSpec, networks: int, limit: Limit, where: str) -> None:
    """Refuse a policy whose networks would not fit (a policy.json from a stranger can say any size)."""
    need = networks * 3 * shape.n_params * FLOAT  # the loaded tensors, the row, acting's views
    if need > limit.bytes:
        raise MemoryLimitExceeded(
            f"{where}: network: {networks} network{'s' * (networks > 1)} of {shape.inputs:,} inputs x "
            f"{shape.hidden_text()} hidden units x {shape.actions:,} outputs would take an estimated {need:,} "
            f"bytes ({_gib(need)}), over the limit of {limit}; refused")
