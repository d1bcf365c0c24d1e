"""Policies as GridWar's earlier trainer (on RuleSim, deleted) wrote them (`tracelab-dqn-policy/1`), for the
tests that such policies still load, converted, or are refused in one line. tests/data/rulesim/base-policy is
one it wrote (tests/data/rulesim/README.md); this writes others of any scenario and weights."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from tracelab.game.scenario import ACTION_NAMES, Scenario
from tracelab.train.qnet import NetSpec

RULESIM_POLICY = Path(__file__).resolve().parent / "data" / "rulesim" / "base-policy"


def constant_weights(net: NetSpec, action: int) -> dict[str, np.ndarray]:
    """A network that always prefers one action: zero weights, a bias of 1 on it."""
    weights = {k: np.zeros(shape, np.float32) for k, shape in net.state_dict_shapes().items()}
    weights["2.bias"][action] = 1.0
    return weights


def write_rulesim_policy(out: Path, scenario: Scenario, net: NetSpec, weights: dict[str, dict[str, np.ndarray]],
                         networks: dict[str, list[int]], stack_previous: bool = False, mask: bool = False) -> Path:
    """policy.json and policy.pt in the folder `out`, as the trainer wrote them: the scenario by name and TOML,
    network name -> its state dict and the red agents it plays."""
    out.mkdir(parents=True)
    torch.save({name: {k: torch.from_numpy(v) for k, v in sd.items()} for name, sd in weights.items()},
               out / "policy.pt")
    spec = {"format": "tracelab-dqn-policy/1",
            "scenario": {"name": scenario.name, "toml": scenario.to_toml()},
            "observation": {"size": net.inputs, "stack_previous": stack_previous, "agent_first": True},
            "actions": {"ids": list(scenario.action_ids), "names": [ACTION_NAMES[a] for a in scenario.action_ids]},
            "network": net.to_json(), "networks": networks, "mask": mask, "trained": {"run": None, "step": 0}}
    (out / "policy.json").write_text(json.dumps(spec, indent=1))
    return out
