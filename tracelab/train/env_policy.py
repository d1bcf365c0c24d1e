"""A trained policy: how it chooses actions, its files, and its greedy evaluation on any env. One policy in
memory, EnvPolicy (TeamPolicy for a world of several agents), read from a policy directory of the format
the trainer writes (docs/training.md, "Policy format"): `tracelab-dqn-env-policy/1` (ENV_FORMAT), one
network over the observations of the env it was trained on (`env`: a registered id or a spec file and its
params; `observation.encoding`), so that play and eval play it on that env and refuse another in one line
(load_env_policy). The war game's earlier policies (RuleSim's trainer's format) are read by its
registration (tracelab/envs/declared/gridwar_scenarios.py) into an EnvPolicy.

A policy is `policy.pt` (`{network name: state dict}`, loaded without running code) beside `policy.json`,
written through write_policy_files. Nothing here needs the training code's objects or the run."""
from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from tracelab.engine.safe_files import read_json
from tracelab.envs.declared.env_source import EnvSource, check_same_env, env_source_from_json
from tracelab.errors import UserError
from tracelab.store import layout
from tracelab.store.agent_rows import PolicyOutput
from tracelab.train.env_source import ObservationEncoder, TeamEncoder, probe_env
from tracelab.train.experiments.stats import spread, wilson
from tracelab.train.memory import check_policy_memory, memory_limit
from tracelab.train.qnet import HiddenWidths, NetSpec, NumpyQ, QFunction
from tracelab.validation import Const, IntRange, ListOf, MapOf, OptionalKey, check_file

# deferred: torch (and torch_files) and the declared envs (the engine) load in the functions that use them:
# reading a policy's spec (policy.json) needs none of them


ENV_FORMAT = "tracelab-dqn-env-policy/1"
POLICY_JSON, POLICY_PT = "policy.json", "policy.pt"
BEST_POLICY_DIR = "policy-best"  # a training run's policy of its best evaluation, beside RUN/policy/


class EnvPolicy:
    """Greedy actions of one network over encoded observations (among the allowed ones when the policy
    masks and the env gives `action_mask`)."""

    def __init__(self, q: QFunction, encoder: ObservationEncoder, mask: bool = False) -> None:
        self.q, self.encoder, self.mask = q, encoder, mask

    def act(self, obs: Any, masks: np.ndarray | None = None) -> np.ndarray:
        return self.decide(obs, masks)[0]

    def decide(self, obs: Any, masks: np.ndarray | None = None) -> tuple[np.ndarray, PolicyOutput]:
        """act()'s actions and the Q-values they were chosen from (unmasked), for a traced game."""
        x = self.encoder(obs)
        terms = getattr(self.q, "term_names", ())  # a decomposed network's: its values by reward term too
        by_term = self.q.per_term(x) if terms else None
        values = by_term.sum(axis=1) if by_term is not None else self.q(x)
        q = np.where(masks.astype(bool), values, -np.inf) if self.mask and masks is not None else values
        return q.argmax(axis=1), PolicyOutput(np.asarray(values, np.float32), terms=terms, term_values=by_term)


class TeamPolicy:
    """One network for every agent of a team (parameter sharing): an EnvPolicy over one agent's rows (a
    TeamEncoder: each agent's observation followed by its one-hot index among the spec's agents, the agent
    indicator of Gupta et al. 2017 and SuperSuit's `agent_indicator_v0`) acting for every agent of a batch
    of worlds: actions [W, agents] from observations [W, agents, ...] and masks [W, agents, A]. What
    env_trainer.py trains on a world of several agents, and plays in its evaluations."""

    def __init__(self, rows: EnvPolicy, n_agents: int) -> None:
        self.rows, self.n_agents = rows, n_agents

    def act(self, obs: Any, masks: np.ndarray | None = None) -> np.ndarray:
        return self.decide(obs, masks)[0]

    def decide(self, obs: Any, masks: np.ndarray | None = None) -> tuple[np.ndarray, PolicyOutput]:
        """The greedy actions [W, agents] and their values [W, agents, A] (a traced world records a row per
        agent)."""
        n = self.n_agents
        worlds = len(obs)
        flat = None if masks is None else np.asarray(masks).reshape(worlds * n, -1)
        actions, out = self.rows.decide(obs, flat)
        terms = None if out.term_values is None else out.term_values.reshape(worlds, n, *out.term_values.shape[1:])
        return actions.reshape(worlds, n), replace(out, values=out.values.reshape(worlds, n, -1), term_values=terms)


def batch_of_one(obs: Any) -> Any:
    """One env's observation as a batch of one (a Dict space's parts each)."""
    if isinstance(obs, dict):
        return {k: np.asarray(v)[None] for k, v in obs.items()}
    return np.asarray(obs)[None]


def one_env_actor(policy: Any, env: Any = None) -> Callable[[Any, dict[str, Any]], int]:
    """The greedy action in one env from its observation and info, of a policy that acts on batches
    (EnvPolicy's `act(obs, masks)`): play --env --policy, traced evaluation games. With a traced `env`
    (a DeclaredEnv with a recorder) and a policy that can `decide`, its output is recorded as the step's
    decision."""
    record = env is not None and getattr(env.unwrapped, "records_decisions", False) and hasattr(policy, "decide")
    decided = env.unwrapped.decided if record else None  # bound once: `unwrapped` walks the wrappers per call

    def act(obs: Any, info: dict[str, Any]) -> int:
        mask = info.get("action_mask")
        masks = None if mask is None else np.asarray(mask)[None]
        if decided is None:
            return int(np.asarray(policy.act(batch_of_one(obs), masks)).reshape(-1)[0])
        actions, output = policy.decide(batch_of_one(obs), masks)
        decided(output, masks)
        return int(np.asarray(actions).reshape(-1)[0])
    return act


def team_env_actor(policy: TeamPolicy, env: Any = None) -> Callable[[Any, dict[str, Any]], np.ndarray]:
    """Every agent's greedy action in one world of several agents (play.TeamEnv: observation [agents, ...],
    masks [agents, A]), each agent's decision recorded where `env` records its games."""
    record = env is not None and getattr(env.unwrapped, "records_decisions", False)

    def act(obs: Any, info: dict[str, Any]) -> np.ndarray:
        mask = info.get("action_mask")
        masks = None if mask is None else np.asarray(mask)[None]
        actions, output = policy.decide(np.asarray(obs)[None], masks)
        if record:
            env.unwrapped.decided(output.rows(0), None if masks is None else masks[0])
        return actions[0]
    return act


def greedy_actor(policy: EnvPolicy | TeamPolicy, env: Any = None) -> Callable[[Any, dict[str, Any]], Any]:
    """The greedy actions in one env of a policy load_trained gave, recorded as the step's decisions where
    `env` records them."""
    return team_env_actor(policy, env) if isinstance(policy, TeamPolicy) else one_env_actor(policy, env)


# ---------------------------------------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------------------------------------
def write_policy_files(out: Path, weights: dict[str, dict[str, Any]], spec: dict[str, Any]) -> Path:
    """policy.pt (weights: network name -> state dict) and policy.json into the folder `out` (a run's
    policy/ or policy-best/), through the store's path resolver: `out` is made or must be a folder, not
    a link, and each file is created new under a temp name and renamed in (never written through a link
    a stranger's run planted there). policy.pt is renamed first: the pair appears together for readers."""
    import torch

    out.parent.mkdir(parents=True, exist_ok=True)  # the run's own folder, which the caller named
    out = layout.make_run_dirs(out.parent, out.name)
    with layout.new_file(layout.run_path(out, POLICY_JSON)) as spec_file, \
            layout.new_file(layout.run_path(out, POLICY_PT)) as weights_file:
        torch.save({name: {k: v.contiguous().clone() for k, v in sd.items()} for name, sd in weights.items()},
                   weights_file)
        spec_file.write((json.dumps(spec, indent=1) + "\n").encode())
    return out


def save_env_policy(path: str | Path, source: EnvSource, weights: dict[str, Any], network: dict[str, Any],
                    encoder: ObservationEncoder, action_names: list[str], mask: bool,
                    trained: dict[str, Any]) -> Path:
    spec = {"format": ENV_FORMAT, "env": source.to_json(),
            "observation": {"size": encoder.size, "encoding": encoder.describe()},
            "actions": {"names": action_names}, "network": network, "networks": {"shared": [0]},
            "mask": mask, "trained": trained}
    return write_policy_files(Path(path), {"shared": weights}, spec)


def policy_dir(path: str | Path) -> Path:
    p = Path(path)
    if p.is_dir():
        return p
    if p.name in (POLICY_JSON, POLICY_PT) and p.parent.is_dir():
        return p.parent
    raise FileNotFoundError(f"no policy at {str(path)!r}: expected a directory holding {POLICY_JSON} and "
                            f"{POLICY_PT} (or the path of one of them)")


NETWORK_SCHEMA = {"inputs": IntRange(1), "hidden": OptionalKey(HiddenWidths()), "outputs": IntRange(1),
                  "dueling": OptionalKey(bool), "custom": OptionalKey(str),
                  "terms": OptionalKey(ListOf(str, min_len=1))}
# what the loaders read of policy.json (the rest describes the policy for people and other tools)
ENV_SPEC_SCHEMA = {
    "format": Const(ENV_FORMAT),
    "env": {"name": str, "kwargs": MapOf(object)},
    "network": NETWORK_SCHEMA,
    "networks": MapOf(ListOf(IntRange(0), min_len=1), min_len=1),
    "mask": OptionalKey(bool),
}



def read_policy_json(path: str | Path) -> tuple[Path, Any]:
    """(policy.json's path, its decoded contents), read with a size cap and without following a link."""
    f = policy_dir(path) / POLICY_JSON
    if not (f.exists() or f.is_symlink()):
        raise FileNotFoundError(f"{str(f.parent)!r} holds no {POLICY_JSON}")
    return f, read_json(f, what="policy description", follow_symlinks=False)


def policy_format(path: str | Path) -> str | None:
    """policy.json's `format` (None when absent or not text): which loader reads the policy."""
    f = policy_dir(path) / POLICY_JSON
    if not f.exists():
        return None
    d = read_json(f, what="policy description", follow_symlinks=False)
    return d.get("format") if isinstance(d, dict) and isinstance(d.get("format"), str) else None


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
    from tracelab.train.torch_files import Tensor
    layers = {k: Tensor(None, shape) for k, shape in net.state_dict_shapes().items()}
    return {name: layers for name in names}


def read_policy_networks(path: str | Path, spec: dict[str, Any]) -> dict[str, Any]:
    """policy.pt of a policy directory, whose policy.json is `spec`: loaded without running code (torch's
    weights_only), no bigger than the networks it declares, each network's state dict of their shape."""
    from tracelab.train.torch_files import load_tensors
    d = policy_dir(path)
    net, names = spec_net(spec), list(spec["networks"])
    check_policy_memory(net, len(names), memory_limit(), str(d / POLICY_JSON))
    f = d / POLICY_PT
    if not (f.exists() or f.is_symlink()):
        raise FileNotFoundError(f"{str(d)!r} holds no {POLICY_PT}")
    # the tensors it declares (float64 at most), with room for the pickle and the alignment torch.save adds
    states = load_tensors(f, len(names) * net.n_params * 8 + (1 << 20))
    return check_file(states, _state_dict_schema(names, net), f)


def numpy_network(net: NetSpec, state: dict[str, Any]) -> NumpyQ:
    return NumpyQ(net, {k: v.float().numpy() for k, v in state.items()})


# ---------------------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------------------
def load_env_policy(path: str | Path, given: EnvSource,
                    world: Any = None) -> tuple[EnvPolicy | TeamPolicy, dict[str, Any]]:
    """(the policy, its policy.json), refused in one line unless it was trained on `given` (the env the
    user named: a policy file never decides which spec file tracelab reads), its network's shape checked
    against the env's spaces (`world`: `given`'s WorldSpec if loaded already, probe_env's). A world of several
    agents: a TeamPolicy (every agent's action)."""
    f, raw = read_policy_json(path)
    spec = check_file(raw, ENV_SPEC_SCHEMA, f)
    check_same_env(env_source_from_json(spec["env"], str(f)), given, str(f.parent))
    net = spec_net(spec)
    states = read_policy_networks(path, spec)
    encoder, n_actions, _ = probe_env(given, world)
    if (encoder.size, n_actions) != (net.inputs, net.actions):
        raise ValueError(f"{f}: its network reads {net.inputs} inputs and gives {net.actions} Q-values; "
                         f"{given.describe()} has {encoder.size} and {n_actions} now")
    policy = EnvPolicy(numpy_network(net, states["shared"]), encoder, spec.get("mask", False))
    return (policy if not isinstance(encoder, TeamEncoder) else TeamPolicy(policy, encoder.n_agents)), spec


def recorded_env(path: str | Path) -> EnvSource | None:
    """The env a policy of train (ENV_FORMAT) was trained on, where it is one of tracelab's registered ids
    (the war game's, the toy-text worlds'), which eval and play then play without --env; None for a spec file or
    another id, which the user names (a policy file never decides which file tracelab reads)."""
    f, raw = read_policy_json(path)
    source = env_source_from_json(check_file(raw, ENV_SPEC_SCHEMA, f)["env"], str(f))
    return source if source.name.startswith("tracelab/") and source.name in gym.registry else None


# ---------------------------------------------------------------------------------------------------------
# Greedy evaluation
# ---------------------------------------------------------------------------------------------------------
@dataclass
class EnvEvalResult:
    """An evaluation's games on any env. Where the world declares how a game ends (a spec's `[end] win`,
    `loss`) its outcomes are counted as the method counted the war game's: wins, losses, draws (ended by
    neither) and truncated games, and the method's win rate, in which a game cut short counts as a loss
    (a spec world's cut is its own step limit, so its method win rate is its win rate); otherwise returns
    and the success rate (return > 0)."""
    returns: list[float] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)
    terminated: int = 0
    truncated: int = 0
    wins: int | None = None  # None: the world declares no outcomes ([end] win / loss)
    losses: int = 0
    draws: int = 0
    win_steps: list[int] = field(default_factory=list, repr=False)  # the won games' lengths
    # wall seconds of the traced and of the untraced games (DeclaredEvaluator.play): a cost, not a result
    seconds: dict[str, float] = field(default_factory=dict, repr=False, compare=False)

    def add(self, ret: float, steps: int, terminated: bool, truncated: bool, outcome: str | None) -> None:
        """One game: its return, length, end flags and declared outcome (None: the world declares none)."""
        self.returns.append(float(ret))
        self.steps.append(int(steps))
        self.terminated += bool(terminated)
        self.truncated += bool(truncated) and not bool(terminated)
        if outcome is None:
            return
        self.wins = (self.wins or 0) + (outcome == "win")
        self.losses += outcome == "loss"
        self.draws += outcome == "terminated"  # ended by neither a win nor a loss
        if outcome == "win":
            self.win_steps.append(int(steps))

    def extend(self, other: "EnvEvalResult") -> None:
        self.returns += other.returns
        self.steps += other.steps
        self.win_steps += other.win_steps
        self.terminated += other.terminated
        self.truncated += other.truncated
        self.losses += other.losses
        self.draws += other.draws
        if other.wins is not None:
            self.wins = (self.wins or 0) + other.wins

    @property
    def games(self) -> int:
        return len(self.returns)

    @property
    def successes(self) -> int:
        """Episodes with a positive return (FrozenLake: the goal reached)."""
        return sum(r > 0 for r in self.returns)

    @property
    def success_rate(self) -> float:
        return self.successes / self.games if self.games else 0.0

    @property
    def mean_return(self) -> float:
        return float(np.mean(self.returns)) if self.returns else 0.0

    @property
    def win_rate(self) -> float | None:
        return None if self.wins is None else (self.wins / self.games if self.games else 0.0)

    @property
    def counts_wins(self) -> bool:
        return self.wins is not None

    def selection(self) -> tuple[str, float]:
        """What the best policy is kept by: the method's win rate where the world declares a win, else
        the mean return (metric name, value)."""
        if self.wins is not None:
            return "eval/method_win_rate", float(self.win_rate or 0.0)
        return "eval/mean_return", self.mean_return

    def metrics(self, prefix: str = "eval/") -> dict[str, float]:
        m = {"games": self.games, "mean_return": self.mean_return, "success_rate": self.success_rate,
             "terminated": self.terminated, "truncated": self.truncated,
             "mean_steps": float(np.mean(self.steps)) if self.steps else 0.0}
        if self.wins is not None:  # the war game's names, which the views plot and the reports read
            m.update(wins=self.wins, losses=self.losses, draws=self.draws, win_rate=self.win_rate,
                     method_win_rate=self.win_rate)
            if self.win_steps:
                m["actions_per_win"] = float(np.mean(self.win_steps))
        return {prefix + k: float(v) for k, v in m.items()}

    def to_dict(self) -> dict[str, Any]:
        d = {k: v for k, v in self.metrics("").items()}
        d["success_rate_ci95"] = list(wilson(self.successes, self.games))
        if self.wins is not None:
            d["win_rate_ci95"] = d["method_win_rate_ci95"] = list(wilson(self.wins, self.games))
        if self.games > 1:
            s = spread(self.returns)
            d["mean_return_ci95"] = [s["ci_low"], s["ci_high"]]
        return d


def make_vector_env(source: EnvSource, worlds: int, by_term: bool = False,
                    kernel: str = "auto", spec: Any = None) -> tuple[Any, str | None]:
    """`worlds` copies of the env stepped together, a world that ends reset within its step (SAME_STEP, as
    the war game's vector env): a declared world's own batched engine (DeclaredVectorEnv, every world in one
    engine call), else gymnasium's SyncVectorEnv over the env. World i steps as the env reset with seed
    s + i either way. `by_term`: each world's reward by term is read (train --decompose), which only a
    world of its own keeps: SyncVectorEnv. `kernel`: the batched engine's (train --kernel). `spec`: the
    declared world's WorldSpec where the caller loaded it already (not parsed again). Returns (the env,
    why a declared world is not batched, or None)."""
    if by_term:
        note = f"{source.short_name}: --decompose reads each world's reward by term; its worlds step in " \
               "gymnasium's SyncVectorEnv"
        return SyncVectorEnv([source.make] * worlds, autoreset_mode=AutoresetMode.SAME_STEP), note
    try:
        spec_file, params = source.declared()
    except UserError:  # not a declared world: any gymnasium env
        return SyncVectorEnv([source.make] * worlds, autoreset_mode=AutoresetMode.SAME_STEP), None
    from tracelab.envs.declared.vector_env import DeclaredVectorEnv
    limit = gym.registry[source.env_id].max_episode_steps if source.env_id is not None else None
    try:
        return DeclaredVectorEnv(spec if spec is not None else spec_file, worlds, max_episode_steps=limit,
                                 kernel=kernel, **params), None
    except ValueError as e:  # a spec the batched engine does not play yet (several agents, draws `after`)
        note = f"{source.short_name}: {str(e).splitlines()[0]}; its worlds step in gymnasium's SyncVectorEnv"
        return SyncVectorEnv([source.make] * worlds, autoreset_mode=AutoresetMode.SAME_STEP), note


def world_spec_of(env: Any) -> Any:
    """The WorldSpec of a declared world's env, vector env (either kind) or None."""
    spec = getattr(env, "world_spec", None)
    if spec is None and getattr(env, "envs", None):
        spec = getattr(env.envs[0].unwrapped, "world_spec", None)
    return spec if spec is not None else getattr(getattr(env, "unwrapped", None), "world_spec", None)


def declares_outcomes(env: Any) -> bool:
    """Whether the env's world declares how a game ends (a spec's `[end] win` or `loss`)."""
    spec = world_spec_of(env)
    return spec is not None and bool(spec.win or spec.loss)


EVAL_STEP_CAP = 10_000  # a greedy policy may walk in circles in an env without a step limit (CliffWalking)


def play_env_games(env: Any, policy: EnvPolicy, games: int, seed: int,
                   on_game: Callable[[float], None] | None = None, step_cap: int = EVAL_STEP_CAP) -> EnvEvalResult:
    """`games` greedy episodes, each world of `env` playing a fixed share (not the first to finish). An
    episode still running after `step_cap` steps ends there, counted truncated."""
    w = env.num_envs
    quota = np.full(w, games // w, np.int64)
    quota[: games % w] += 1
    result = EnvEvalResult()
    declares = declares_outcomes(env)
    obs, info = env.reset(seed=seed)
    ret, length = np.zeros(w), np.zeros(w, np.int64)
    while quota.any():
        actions = policy.act(obs, info.get("action_mask"))
        obs, reward, term, trunc, info = env.step(actions)
        ret += reward
        length += 1
        capped = (length >= step_cap) & ~(term | trunc)
        trunc = trunc | capped
        outcomes = info.get("final_info", {}).get("outcome")  # where the world declares how games end
        for k in np.flatnonzero((term | trunc) & (quota > 0)).tolist():
            outcome = None if not declares else "truncated" if capped[k] or outcomes is None else str(outcomes[k])
            result.add(float(ret[k]), int(length[k]), bool(term[k]), bool(trunc[k]), outcome)
            quota[k] -= 1
            if on_game is not None:
                on_game(float(ret[k]))
        done = term | trunc
        ret[done], length[done] = 0.0, 0
        if capped.any():  # the env did not end them: reset those worlds only
            obs, info = _reset_worlds(env, obs, info, capped)
    return result


def _reset_worlds(env: Any, obs: Any, info: dict[str, Any], worlds: np.ndarray) -> tuple[Any, dict[str, Any]]:
    new_obs, new_info = env.reset(options={"reset_mask": worlds})
    obs = np.where(worlds.reshape(-1, *([1] * (np.ndim(obs) - 1))), new_obs, obs)
    if "action_mask" in info:
        info = {**info, "action_mask": np.where(worlds[:, None], new_info["action_mask"], info["action_mask"])}
    return obs, info


def evaluate_env(policy: EnvPolicy, source: EnvSource, games: int, seed: int, worlds: int = 16,
                 on_game: Callable[[float], None] | None = None, spec: Any = None) -> EnvEvalResult:
    """`games` greedy games in `worlds` worlds stepped together (make_vector_env's; `spec`: its WorldSpec
    if loaded already)."""
    env, _ = make_vector_env(source, min(worlds, games), spec=spec)
    try:
        return play_env_games(env, policy, games, seed, on_game)
    finally:
        env.close()


def evaluate_in_env(policy: Any, env: Any, games: int, seed: int,
                    on_game: Callable[[float], None] | None = None) -> EnvEvalResult:
    """`games` greedy episodes of a policy load_trained gave, one at a time in `env` (a declared world's Env
    or TeamEnv: every game traced with its decisions where `env` records), counted as evaluate_env counts."""
    from tracelab.envs.declared.play import play_episodes
    declares = declares_outcomes(env)
    result = EnvEvalResult()

    def ended(game: dict[str, Any]) -> None:
        cut = game["outcome"] == "truncated"
        result.add(game["return"], game["steps"], not cut, cut, game["outcome"] if declares else None)
        if on_game is not None:
            on_game(game["return"])
    play_episodes(env, games, seed, greedy_actor(policy, env), on_episode=ended, step_cap=EVAL_STEP_CAP)
    return result
