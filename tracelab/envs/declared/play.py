"""Games of a declared world (a spec file or a registered id such as tracelab/FrozenLake-v1, an
env_source.EnvSource; the war game's scenarios through their specs, gridwar.scenario_spec), played by a random or
a trained policy: its spec, its env (TeamEnv for a world of several agents), and the play loop. `tracelab
play` (tracelab/commands/play.py) records them into a run."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.history import ObservationHistory
from tracelab.envs.declared.spec import WorldSpec, load_spec

if TYPE_CHECKING:
    from tracelab.store.agent_rows import PolicyOutput
    from tracelab.store.writer import TraceWriter

# deferred: the declared env and world load the engine (numba), once a world is built (a registered id goes through
# gym.make); the recorder loads the store (DuckDB) for a traced world only


def make_declared_env(source: EnvSource, spec: WorldSpec, **options: Any) -> Any:
    """The env of `source` over its loaded `spec`, with `options` (kernel, trace_writer): an id through
    gym.make (its step limit, TimeLimit, which the traced env reads from its EnvSpec), a file as it is; a
    world of several agents as a TeamEnv."""
    if len(spec.agents) != 1:
        return TeamEnv(spec, **options)
    if source.env_id is not None:
        return gym.make(source.env_id, spec=spec, **options)
    from tracelab.envs.declared.gym_env import DeclaredEnv
    return DeclaredEnv(spec, **options)


def load_declared(source: EnvSource) -> WorldSpec:
    """The checked spec of a declared world (SpecError, a located user error, for a wrong file or keyword
    argument; UserError for a source that is not a declared world)."""
    spec_path, params = source.declared()
    return load_spec(spec_path, **params)


class TeamEnv:
    """A declared world of several agents, played by one policy for all of them, as play_episodes plays an
    Env: the observation [agents, ...] (each agent's), `info["action_mask"]` [agents, actions], a step takes
    an action per agent and gives the agents' summed reward; `info["outcome"]` at the end where the world
    declares one. Seeded as DeclaredParallelEnv (the same draws); `trace_writer`: the run its games go to
    (`trace_episode_ids`: their episode ids, where the run is another's, as DeclaredEnv's)."""

    def __init__(self, spec: WorldSpec, *, kernel: str = "auto", trace_writer: TraceWriter | None = None,
                 trace_episode_ids: Callable[[], int] | None = None, trace_agent_rows: bool = True) -> None:
        from tracelab.envs.declared.world import DeclaredWorld
        self.world_spec = spec
        self.world = DeclaredWorld(spec, kernel=kernel, trace=trace_writer is not None)
        self.n_agents = len(spec.agents)
        self.action_space = gym.spaces.Discrete(len(spec.action_names))
        self._histories = [ObservationHistory(spec.previous) for _ in spec.agents]
        self._rng = np.random.default_rng()
        self._recorder = None
        if trace_writer is not None:
            from tracelab.envs.declared.recording import DeclaredRecorder
            self._recorder = DeclaredRecorder(self.world, trace_writer, trace_episode_ids, trace_agent_rows)

    @property
    def unwrapped(self) -> "TeamEnv":
        return self

    @property
    def records_decisions(self) -> bool:
        return self._recorder is not None

    def decided(self, output: "PolicyOutput", mask: np.ndarray | None = None) -> None:
        """The policy's output for the next step, one row per agent (recorded as its decisions)."""
        if self._recorder is not None:
            self._recorder.decided(output, mask)

    def trace_info(self, info: dict[str, Any] | None) -> None:
        """The begin info of the games it records from its next reset on (DeclaredEnv.trace_info)."""
        if self._recorder is not None:
            self._recorder.begin_info = info

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        if seed is not None:
            self._rng, _ = gym.utils.seeding.np_random(seed)
        if self._recorder is not None:
            self._recorder.before_reset()
        self.world.reset(self._rng)
        if self._recorder is not None:
            self._recorder.begin(seed)
        return self._observe(start=True), self._info()

    def step(self, actions: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        rows = np.asarray(actions, np.int64).reshape(self.n_agents)
        w = self.world
        w.step(rows, self._rng)
        terminated, truncated = w.terminated(), w.truncated()
        obs = self._observe()
        if self._recorder is not None:  # the team's view (each agent's is the same in war.toml) as the step's
            self._recorder.stepped(rows, w.last_rewards, obs[0], terminated, truncated)
        info = self._info()
        if (self.world_spec.win or self.world_spec.loss) and (terminated or truncated):
            info["outcome"] = w.outcome()
        return obs, float(sum(w.last_rewards)), terminated, truncated, info

    def close(self, status: str = "finished") -> None:
        if self._recorder is not None:
            recorder, self._recorder = self._recorder, None
            recorder.close(status)

    def _observe(self, start: bool = False) -> np.ndarray:
        return np.stack([(h.start if start else h.step)(self.world.observation(i))
                         for i, h in enumerate(self._histories)])

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {"t": self.world.steps}
        if self.world.action_mask(0) is not None:
            info["action_mask"] = np.stack([self.world.action_mask(i) for i in range(self.n_agents)])
        return info


def random_policy(env: Any, seed: int) -> Callable[[Any, dict[str, Any]], Any]:
    """Uniform over the actions (over the allowed ones when the env gives an action mask); an action per
    agent of a TeamEnv."""
    rng = np.random.default_rng(seed)
    n = int(env.action_space.n)

    def one(mask: np.ndarray | None) -> int:
        if mask is not None and mask.any():
            return int(rng.choice(np.flatnonzero(mask)))
        return int(rng.integers(0, n))

    agents = getattr(env.unwrapped, "n_agents", None)
    if agents is None:
        return lambda obs, info: one(info.get("action_mask"))

    def act(obs: Any, info: dict[str, Any]) -> np.ndarray:
        masks = info.get("action_mask")
        return np.array([one(None if masks is None else masks[j]) for j in range(agents)])
    return act


def play_episodes(env: gym.Env, episodes: int, seed: int, act: Callable[[Any, dict[str, Any]], int],
                  on_episode: Callable[[dict[str, Any]], None] | None = None,
                  step_cap: int | None = None) -> dict[str, Any]:
    """Play `episodes` episodes (the first reset seeded with `seed`, the others continuing its stream);
    returns each episode's steps, return and outcome, the steps and the seconds they took. `step_cap`: an
    episode still running after that many steps ends there, counted truncated (a traced one's record ends
    'aborted' at the next reset)."""
    out: list[dict[str, Any]] = []
    steps = 0
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    for e in range(episodes):
        if e:
            obs, info = env.reset()
        ret, n, terminated, truncated = 0.0, 0, False, False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, info = env.step(act(obs, info))
            ret += float(reward)
            n += 1
            truncated = truncated or (step_cap is not None and n >= step_cap and not terminated)
        steps += n
        # the env's own outcome where the world declares a win ([end] win: "win" or "loss")
        outcome = info.get("outcome", "terminated") if terminated else "truncated"
        out.append({"steps": n, "return": ret, "outcome": outcome})
        if on_episode is not None:
            on_episode(out[-1])
    return {"episodes": out, "steps": steps, "seconds": time.perf_counter() - t0}
