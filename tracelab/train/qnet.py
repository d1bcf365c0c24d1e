"""The Q-network, described once (`NetSpec`): its layers, their parameters' names and shapes, and the
initial weights a seed draws (`draw_weights`). Everything else is derived from it: the torch module the
readable learner trains (tracelab/train/dqn.py, `make_q_network`), the fused learner's flat parameter row
(tracelab/train/network.py), the policy files and the checkpoints' schemas, and acting in numpy (`NumpyQ`).

The architecture travels in files a stranger may hand us (policy.json, a checkpoint's config), so it is
described, not pickled: tanh hidden layers of the given widths, then one Q-value per action, or a dueling
head (V(s) + A(s, a) - mean_a A(s, a)). From that description alone tracelab knows every parameter's name
and shape (to check a file before using it, and to bound its memory) and computes Q-values in numpy (acting
reads the learner's live weights without torch's per-call overhead).

A network written through the Python API as any `torch.nn.Module` has no such description: it acts
through torch (`TorchQ`), and its policy files say `custom` (docs/training.md)."""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from tracelab.validation import Mismatch, Spec

# deferred: torch, in the functions that build a torch network: config.py imports this module, and train's parser
# (tracelab --help) imports config.py

QFunction = Callable[[np.ndarray], np.ndarray]  # observations [K, D] -> Q-values [K, A]
MAX_LAYERS = 32  # hidden layers a config or a policy file may declare (a stranger's file could say millions)


def parse_hidden(text: str | int) -> tuple[int, ...]:
    """'64,64' (or 64) -> (64, 64); ValueError naming the value otherwise."""
    parts = [p.strip() for p in str(text).split(",", MAX_LAYERS)]
    if len(parts) > MAX_LAYERS or not all(p.isdigit() and int(p) >= 1 for p in parts):
        raise ValueError(f"hidden must be up to {MAX_LAYERS} layer widths >= 1 separated by commas (64 or "
                         f"64,64), got {str(text)[:80]!r}")
    return tuple(int(p) for p in parts)


@dataclass(frozen=True)
class NetSpec:
    inputs: int
    hidden: tuple[int, ...]
    actions: int
    dueling: bool = False
    # reward decomposition (`train --decompose`): one Q head per reward term, the output layer holding each
    # term's Q-values of every action back to back ([term, action]); Q is their sum
    terms: tuple[str, ...] = ()

    @property
    def outputs(self) -> int:
        """The output layer's width: one Q-value per action, per reward term when decomposed."""
        return self.actions * max(1, len(self.terms))

    def linears(self) -> list[tuple[str, int, int]]:
        """(state dict prefix, fan in, fan out) of each linear layer, in the order the module holds them:
        nn.Sequential's indices (a Tanh between two Linears), the dueling head's named parts."""
        widths = (self.inputs, *self.hidden)
        trunk = [(str(2 * i), a, b) for i, (a, b) in enumerate(zip(widths, widths[1:]))]
        last = widths[-1]
        if not self.dueling:
            return [*trunk, (str(2 * len(self.hidden)), last, self.outputs)]
        return [(f"trunk.{k}", a, b) for k, a, b in trunk] + [("value", last, 1), ("advantage", last, self.actions)]

    def state_dict_shapes(self) -> dict[str, tuple[int, ...]]:
        out: dict[str, tuple[int, ...]] = {}
        for name, fan_in, fan_out in self.linears():
            out[f"{name}.weight"], out[f"{name}.bias"] = (fan_out, fan_in), (fan_out,)
        return out

    @property
    def n_params(self) -> int:
        return sum((fan_in + 1) * fan_out for _, fan_in, fan_out in self.linears())

    def hidden_text(self) -> str:
        return ",".join(f"{h:,}" if len(self.hidden) == 1 else str(h) for h in self.hidden)

    def torch_text(self) -> str:
        """The module as torch code, for people reading policy.json."""
        widths = (self.inputs, *self.hidden)
        trunk = ", ".join(f"nn.Linear({a}, {b}), nn.Tanh()" for a, b in zip(widths, widths[1:]))
        if self.terms:
            return (f"nn.Sequential({trunk}, nn.Linear({widths[-1]}, {self.outputs})); Q per term = output.view(-1, "
                    f"{len(self.terms)}, {self.actions}) (terms {', '.join(self.terms)}), Q = its sum over terms")
        if not self.dueling:
            return f"nn.Sequential({trunk}, nn.Linear({widths[-1]}, {self.actions}))"
        return (f"dueling: trunk = nn.Sequential({trunk}), value = nn.Linear({widths[-1]}, 1), advantage = "
                f"nn.Linear({widths[-1]}, {self.actions}); Q = value + advantage - advantage.mean(1)")

    def to_json(self) -> dict[str, Any]:
        """policy.json's `network` (a one-layer network keeps `hidden` a number, as before dueling)."""
        out = {"inputs": self.inputs, "hidden": self.hidden[0] if len(self.hidden) == 1 else list(self.hidden),
               "outputs": self.actions, "dueling": self.dueling, "activation": "tanh",
               "state_dict_keys": list(self.state_dict_shapes()), "torch": self.torch_text()}
        return {**out, "terms": list(self.terms)} if self.terms else out

    @classmethod
    def from_json(cls, net: dict[str, Any]) -> "NetSpec":
        """policy.json's `network` (`terms`: absent in a plain network's and in files written before)."""
        h = net["hidden"]
        return cls(net["inputs"], (h,) if isinstance(h, int) else tuple(h), net["outputs"], net.get("dueling", False),
                   tuple(net.get("terms", ())))


def draw_weights(spec: NetSpec, generator: Any = None) -> dict[str, Any]:
    """The network's initial weights as a state dict: nn.Linear's default initialisation (uniform in
    ±1/sqrt(fan_in), weight then bias, layer by layer in `linears()` order) drawn from a seeded torch
    generator. Both learners start from these, so the same seed draws the same network in either."""
    import torch
    weights = {}
    for name, fan_in, fan_out in spec.linears():
        bound = 1 / math.sqrt(fan_in)
        w_t = torch.empty(fan_in, fan_out).uniform_(-bound, bound, generator=generator)
        weights[f"{name}.weight"] = w_t.t().contiguous()
        weights[f"{name}.bias"] = torch.empty(fan_out).uniform_(-bound, bound, generator=generator)
    return weights


class HiddenWidths(Spec):
    """policy.json's network.hidden: a width, or a non-empty list of widths (each an integer >= 1)."""
    expected = f"an integer >= 1 (or a list of up to {MAX_LAYERS} of them)"

    def check(self, value: Any, where: str) -> None:
        items = value if isinstance(value, list) and value else [value]
        if len(items) > MAX_LAYERS or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in items):
            raise Mismatch(where, self.expected, value)


class NumpyQ:
    """Q-values of a NetSpec network from its weights as numpy arrays named as in its state dict (views of
    the learner's live parameters while training, loaded copies otherwise)."""

    def __init__(self, spec: NetSpec, weights: Mapping[str, np.ndarray]) -> None:
        self.dueling, self.terms, self.actions = spec.dueling, len(spec.terms), spec.actions
        self.term_names = spec.terms
        self.layers = [(weights[f"{name}.weight"].T, weights[f"{name}.bias"]) for name, _, _ in spec.linears()]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if self.terms:
            return self.per_term(obs).sum(axis=1)
        x = obs
        heads = 2 if self.dueling else 1
        for w, b in self.layers[:-heads]:
            x = np.tanh(x @ w + b)
        if not self.dueling:
            w, b = self.layers[-1]
            return x @ w + b
        (wv, bv), (wa, ba) = self.layers[-2:]
        adv = x @ wa + ba
        return x @ wv + bv + adv - adv.mean(axis=1, keepdims=True)

    def per_term(self, obs: np.ndarray) -> np.ndarray:
        """A decomposed network's Q-values by reward term, [K, terms, A] (their sum over terms is Q)."""
        x = obs
        for w, b in self.layers[:-1]:
            x = np.tanh(x @ w + b)
        w, b = self.layers[-1]
        return (x @ w + b).reshape(len(x), self.terms, self.actions)


class TorchQ:
    """Q-values of any torch module (a custom network), without gradients."""

    def __init__(self, module: Any) -> None:
        self.module = module

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        import torch
        with torch.no_grad():
            return self.module(torch.from_numpy(np.ascontiguousarray(obs, np.float32))).numpy()
