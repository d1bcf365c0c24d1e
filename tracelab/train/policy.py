"""A trained policy: how red's agents choose actions from the team observation, and its file format.

Each red agent sees the team observation reordered so that its own blocks come first (its position before
its team mates', its bullet triple first in the advanced scenario; both halves of a stacked observation
alike): with one network shared by several agents (the Markov setup) that is how the network knows which
agent it acts for. With one agent per team the order is the env's.

On disk (docs/training.md, "Policy format"): `policy.pt` holds `{network name: state dict}` (the method's
network in nn.Sequential(Linear(D, H), Tanh(), Linear(H, A))'s names), `policy.json` the scenario, the
observation layout, the action ids, the network's architecture (tracelab/train/qnet.py) and which agents
each network plays. `load_policy` needs neither the training code's objects nor the run."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.engine.safe_files import read_json
from tracelab.store import layout
from tracelab.game.scenario import ACTION_NAMES, NOTHING, Scenario, scenario_from_dict
from tracelab.store.agent_rows import PolicyOutput
from tracelab.train.memory import check_policy_memory, memory_limit
from tracelab.validation import Const, IntRange, ListOf, MapOf, OptionalKey, check_file
from tracelab.train.qnet import HiddenWidths, NetSpec, NumpyQ, QFunction

FORMAT = "tracelab-dqn-policy/1"
POLICY_JSON, POLICY_PT = "policy.json", "policy.pt"
BEST_POLICY_DIR = "policy-best"  # a training run's policy of its best evaluation, beside RUN/policy/


def agent_view_order(scenario: Scenario, stack_previous: bool) -> np.ndarray:
    """int [N, D]: agent j's observation is team_obs[..., order[j]] (its own blocks first)."""
    n = scenario.agents_per_team
    block = (7 if scenario.advanced else 4) * n
    orders = []
    for j in range(n):
        mates = [j] + [k for k in range(n) if k != j]
        half = [2 * k + c for k in mates for c in (0, 1)]             # own positions
        half += [2 * n + c for c in range(2 * n)]                     # opponents, as they are
        if scenario.advanced:
            half += [4 * n + 3 * k + c for k in mates for c in range(3)]  # own bullet triples
        if stack_previous:
            half = half + [block + i for i in half]
        orders.append(half)
    return np.asarray(orders, np.int64)


def may_act(scenario: Scenario, state: Any, slow_every_step: bool = False) -> np.ndarray:
    """bool [W, N]: which red agents choose an action this step (alive; a slow agent on even steps, or on
    every step with `slow_every_step`: the game ignores its choices where it may not act)."""
    if slow_every_step:
        return state.alive[:, 0].copy()
    return state.choosing(scenario.slow_mask)[:, 0]


class Policy:
    """Greedy action choice of red's agents. `nets`: per network, its Q-values of observations [K, D] (from
    the learner's live weights while training, loaded ones otherwise); `network_of_agent[j]` which one
    plays agent j."""

    def __init__(self, scenario: Scenario, nets: list[QFunction], network_of_agent: list[int],
                 stack_previous: bool, mask: bool = False) -> None:
        self.scenario = scenario
        self.nets = nets
        self.network_of_agent = list(network_of_agent)
        self.stack_previous = stack_previous
        self.mask = mask
        self.order = agent_view_order(scenario, stack_previous)
        self.nothing = scenario.action_ids.index(NOTHING)
        self._identity = scenario.agents_per_team == 1

    def agent_obs(self, team_obs: np.ndarray, j: int) -> np.ndarray:
        """Agent j's view [W, D] of the team observations [W, D]."""
        return team_obs if self._identity else team_obs[:, self.order[j]]

    def act(self, team_obs: np.ndarray, acting: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray:
        """Action indices [W, N]: greedy for acting agents (among allowed ones if the policy masks and
        `masks` [W, N, A] is given), do-nothing for the others."""
        return self.decide(team_obs, acting, masks)[0]

    def decide(self, team_obs: np.ndarray, acting: np.ndarray, masks: np.ndarray | None = None
               ) -> tuple[np.ndarray, PolicyOutput]:
        """act()'s actions [W, N] and the Q-values they were chosen from ([W, N, A], unmasked; NaN for
        agents that do not act), for a traced game's decisions (tracelab.store.agent_rows)."""
        w, n = acting.shape
        if n == 1 and acting.all():  # one agent, choosing in every world (the 1v1 games): no copies
            values = self.nets[self.network_of_agent[0]](team_obs)
            q = np.where(masks[:, 0].astype(bool), values, -np.inf) if self.mask and masks is not None else values
            return q.argmax(axis=1)[:, None], PolicyOutput(values[:, None])
        out = np.full((w, n), self.nothing, np.int64)
        values = np.full((w, n, self.scenario.n_actions), np.nan, np.float32)
        for j in range(n):
            rows = np.flatnonzero(acting[:, j])
            if not len(rows):
                continue
            q = self.nets[self.network_of_agent[j]](self.agent_obs(team_obs[rows], j))
            values[rows, j] = q
            if self.mask and masks is not None:
                q = np.where(masks[rows, j].astype(bool), q, -np.inf)
            out[rows, j] = q.argmax(axis=1)
        return out, PolicyOutput(values)


# ---------------------------------------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------------------------------------
def save_policy(path: str | Path, scenario: Scenario, weights: dict[str, dict[str, Any]],
                agents: dict[str, list[int]], network: dict[str, Any], stack_previous: bool, mask: bool,
                trained: dict[str, Any]) -> Path:
    """Write policy.pt and policy.json into directory `path`. weights: network name -> its state dict;
    agents: network name -> red agent indices it plays; network: policy.json's description of the
    architecture (NetSpec.to_json, or a custom module's)."""
    # deferred: the game's observation module loads numba, which reading a policy's spec does not need
    from tracelab.game.observe import observation_layout
    spec = {
        "format": FORMAT,
        "scenario": {"name": scenario.name, "toml": scenario.to_toml()},
        "observation": {"size": network["inputs"], "stack_previous": stack_previous, "agent_first": True,
                        "layout": observation_layout(scenario, stack_previous)},
        "actions": {"ids": list(scenario.action_ids), "names": [ACTION_NAMES[a] for a in scenario.action_ids]},
        "network": network,
        "networks": {name: list(map(int, idx)) for name, idx in agents.items()},
        "mask": mask,
        "trained": trained,
    }
    return write_policy_files(Path(path), weights, spec)


def write_policy_files(out: Path, weights: dict[str, dict[str, Any]], spec: dict[str, Any]) -> Path:
    """policy.pt (weights: network name -> state dict) and policy.json into the folder `out` (a run's
    policy/ or policy-best/), through the store's path resolver: `out` is made or must be a folder, not
    a link, and each file is created new under a temp name and renamed in (never written through a link
    a stranger's run planted there). policy.pt is renamed first: the pair appears together for readers."""
    import torch  # deferred: reading a policy's spec does not need it

    out.parent.mkdir(parents=True, exist_ok=True)  # the run's own folder, which the caller named
    out = layout.make_run_dirs(out.parent, out.name)
    with layout.new_file(layout.run_path(out, POLICY_JSON)) as spec_file, \
            layout.new_file(layout.run_path(out, POLICY_PT)) as weights_file:
        torch.save({name: {k: v.contiguous().clone() for k, v in sd.items()} for name, sd in weights.items()},
                   weights_file)
        spec_file.write((json.dumps(spec, indent=1) + "\n").encode())
    return out


def _policy_dir(path: str | Path) -> Path:
    p = Path(path)
    if p.is_dir():
        return p
    if p.name in (POLICY_JSON, POLICY_PT) and p.parent.is_dir():
        return p.parent
    raise FileNotFoundError(f"no policy at {str(path)!r}: expected a directory holding {POLICY_JSON} and "
                            f"{POLICY_PT} (or the path of one of them)")


# what load_policy reads of policy.json (the rest describes the policy for people and other tools)
SPEC_SCHEMA = {
    "format": Const(FORMAT),
    "scenario": {"name": str, "toml": str},
    "observation": {"stack_previous": bool},
    "network": {"inputs": IntRange(1), "hidden": OptionalKey(HiddenWidths()), "outputs": IntRange(1),
                "dueling": OptionalKey(bool), "custom": OptionalKey(str), "terms": OptionalKey(ListOf(str, min_len=1))},
    "networks": MapOf(ListOf(IntRange(0), min_len=1), min_len=1),
    "mask": OptionalKey(bool),
}


def read_policy_spec(path: str | Path) -> dict[str, Any]:
    """policy.json of a policy directory, read with a size cap and checked against SPEC_SCHEMA (a policy
    may come from a stranger: each failure is one line naming the key)."""
    d = _policy_dir(path)
    f = d / POLICY_JSON
    if not (f.exists() or f.is_symlink()):
        raise FileNotFoundError(f"{str(d)!r} holds no {POLICY_JSON}")
    spec = read_json(f, what="policy description", follow_symlinks=False)
    return check_file(spec, SPEC_SCHEMA, f)


def policy_scenario(spec: dict[str, Any]) -> Scenario:
    return scenario_from_dict(tomllib.loads(spec["scenario"]["toml"]), source="policy.json scenario")


def spec_net(spec: dict[str, Any]) -> NetSpec:
    """The architecture policy.json describes (ValueError for a custom module's: no file rebuilds one)."""
    net = spec["network"]
    if "custom" in net or "hidden" not in net:
        raise ValueError(f"{POLICY_JSON}: network: a custom torch module ({net.get('custom', '?')[:80]}), "
                         f"written through the Python API: tracelab rebuilds only the networks --hidden and "
                         f"--dueling describe; load its policy.pt with torch into that module")
    return NetSpec.from_json(net)


def _state_dict_schema(names: list[str], net: NetSpec) -> dict[str, Any]:
    """policy.pt: per network, the state dict of the module `net` describes."""
    # deferred: torch_files loads torch
    from tracelab.train.torch_files import Tensor
    layers = {k: Tensor(None, shape) for k, shape in net.state_dict_shapes().items()}
    return {name: layers for name in names}


def read_policy_networks(path: str | Path, spec: dict[str, Any]) -> dict[str, Any]:
    """policy.pt of a policy directory, whose policy.json is `spec`: loaded without running code (torch's
    weights_only), no bigger than the networks it declares, each network's state dict of their shape."""
    # deferred: torch_files loads torch
    from tracelab.train.torch_files import load_tensors
    d = _policy_dir(path)
    net, names = spec_net(spec), list(spec["networks"])
    check_policy_memory(net, len(names), memory_limit(), str(d / POLICY_JSON))
    f = d / POLICY_PT
    if not (f.exists() or f.is_symlink()):
        raise FileNotFoundError(f"{str(d)!r} holds no {POLICY_PT}")
    # the tensors it declares (float64 at most), with room for the pickle and the alignment torch.save adds
    states = load_tensors(f, len(names) * net.n_params * 8 + (1 << 20))
    return check_file(states, _state_dict_schema(names, net), f)


def load_policy(path: str | Path, scenario: Scenario | None = None) -> Policy:
    """A saved policy, ready to act. `scenario`: play it on another scenario of the same shape (same
    agents, actions and observation size); default: the one it was trained on."""
    spec = read_policy_spec(path)
    trained_on = policy_scenario(spec)
    scenario = scenario or trained_on
    stack = spec["observation"]["stack_previous"]
    net = spec_net(spec)
    # deferred: the game's observation module loads numba
    from tracelab.game.observe import obs_size
    if (obs_size(scenario, stack), scenario.n_actions, scenario.agents_per_team) != \
            (net.inputs, net.actions, trained_on.agents_per_team):
        raise ValueError(f"the policy was trained on {trained_on.name!r} ({trained_on.agents_per_team} agents, "
                         f"{net.inputs} observations, {net.actions} actions); scenario {scenario.name!r} "
                         f"does not match")
    states = read_policy_networks(path, spec)
    nets: list[QFunction] = []
    owner = {}
    for i, name in enumerate(spec["networks"]):
        nets.append(NumpyQ(net, {k: v.float().numpy() for k, v in states[name].items()}))
        for j in spec["networks"][name]:
            owner[j] = i
    if sorted(owner) != list(range(scenario.agents_per_team)):
        raise ValueError(f"{POLICY_JSON}: networks {spec['networks']} do not cover agents "
                         f"0..{scenario.agents_per_team - 1}")
    return Policy(scenario, nets, [owner[j] for j in range(scenario.agents_per_team)], stack,
                  spec.get("mask", False))
