"""`GridWarVectorEnv`: `num_envs` games of the learner (red) against the scripted opponent, stepped by one
simulator call per step (RuleSim / RefSim with n_worlds = num_envs). Spaces, rewards, infos and backends
are red's (docs/game.md, Observations), batched:
- Action: an index into `scenario.action_ids` per world (Discrete), one per agent (MultiDiscrete) for more.
- info: `action_mask`, `t`, `winner` (-1 none, 0 red, 1 blue, 2 draw), `opponent_actions` and red's
  per-agent `unsafe`, `invalid`, `hits_made`, `hits_taken`, `agent_reward` (step_info).

Autoreset: SAME_STEP (`metadata["autoreset_mode"]`). A world whose episode ends in a step is reset
within that step: the step returns its terminal reward and terminated/truncated flags, but the reset
observation, so every transition (obs, action, reward, next obs) lies inside one episode once the
replay buffer takes next obs from `final_obs` where `_final_obs` is set. As in gymnasium 1.x:
- info["final_obs"]: float32 [num_envs, D], the terminal observations (rows valid where
  info["_final_obs"] is True; a dense array rather than an object array, to stay vectorised);
- info["final_info"]: the step's info at the end of the episode (same keys, each with its `_key`
  mask = the worlds that ended); info["_final_info"] marks those worlds;
- the top-level info describes the returned observation: for a reset world that is the reset info
  (t = 0, zero events, the new episode's action_mask).
Every info key has its gymnasium `_key` mask. (Gymnasium's observation wrappers accept only NEXT_STEP;
RecordEpisodeStatistics supports SAME_STEP.)

`copy` (gymnasium's SyncVectorEnv switch, default True): with True, reset() and step() return a new
observation array each time; with False, the observation is a buffer of the env's that its next step or
reset overwrites (rewards, flags and infos are new arrays either way, as in gymnasium).

Seeding: one generator drives the opponent in every world; reset(seed=s) reseeds it, so a run is
reproducible for a given seed and num_envs. A list of seeds is combined into one (SeedSequence).

Tracing: with `trace_sink`, every episode goes to the sink; with `trace_episodes=N` too, only the
episodes 0..N-1 (ids in the order episodes begin; see tracelab/envs/tracer.py), so stepping until those
ended records exactly N episodes. The sink also gets the reward terms of each step and the decisions
a caller hands over with `decided()` before a step; `trace_agent=False`: neither (docs/envs.md).

`kernel`: the rule engine's kernel (backend "rules"; tracelab.envs.common.make_sim): auto, counting,
lanes or compiled (built in the background while the env steps on the counting kernel if not cached).

`opponent_p`: the scripted opponent's probability of a move towards red's base (0.7, the method's
training setting). info["opponent_actions"] (int64, spec ids) holds what blue played in
the step (in final_info for worlds that ended), so a step can be replayed on a simulator
(`sim.step(red, blue)`), e.g. to restore a checkpoint.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from tracelab.envs.declared.vector_env import with_masks
from tracelab.envs.common import (
    ActionMasker,
    learner_action_space,
    make_sim,
    observation_space,
    reset_sim,
    resolve_scenario,
    restart_worlds,
    step_learner,
)
from tracelab.envs.sinks import TraceSink
from tracelab.envs.tracer import EpisodeTracer
from tracelab.store.agent_rows import PolicyOutput
from tracelab.game.opponent import P_TOWARD
from tracelab.game.scenario import RED, Scenario
from tracelab.game.state import WINNER_NONE, StepResult


def step_info(res: StepResult, masks: np.ndarray, one_agent: bool, opponent: np.ndarray) -> dict[str, Any]:
    """info of every world after a step, arrays [W, ...] (red's view); masks: [W, N, n_actions];
    opponent: blue's actions (spec ids, [W, N]). With one agent per team the agent axis is dropped
    (masks [W, n_actions], events [W]). Every array is new: the StepResult's are the simulator's buffers."""
    info = {"action_mask": masks, "opponent_actions": np.asarray(opponent, np.int64),
            "unsafe": res.unsafe[:, RED].copy(), "invalid": res.invalid[:, RED].copy(),
            "hits_made": res.hits_made[:, RED].astype(np.int64),
            "hits_taken": res.hits_taken[:, RED].astype(np.int64), "agent_reward": res.agent_reward[:, RED].copy()}
    if one_agent:
        info = {k: v[:, 0] for k, v in info.items()}
    return {"t": res.t.astype(np.int64), "winner": res.winner.astype(np.int64), **info}


def reset_info(n_worlds: int, masks: np.ndarray, one_agent: bool) -> dict[str, Any]:
    """info of worlds at the start of an episode: nothing has happened yet."""
    shape = (n_worlds,) if one_agent else (n_worlds, masks.shape[1])
    return {"t": np.zeros(n_worlds, np.int64), "winner": np.full(n_worlds, WINNER_NONE, np.int64),
            "action_mask": masks[:, 0] if one_agent else masks, "opponent_actions": np.full(shape, -1, np.int64),
            "unsafe": np.zeros(shape, bool),
            "invalid": np.zeros(shape, bool), "hits_made": np.zeros(shape, np.int64),
            "hits_taken": np.zeros(shape, np.int64), "agent_reward": np.zeros(shape)}


def _batch_seed(seed: int | Sequence[int] | None) -> int | None:
    if seed is None or isinstance(seed, (int, np.integer)):
        return None if seed is None else int(seed)
    return int(np.random.SeedSequence([int(s) for s in seed]).generate_state(1, np.uint64)[0])


class GridWarVectorEnv(VectorEnv):
    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, scenario: Scenario | str = "advanced", *, backend: str = "rules",
                 stack_previous: bool = False, trace_sink: TraceSink | None = None,
                 trace_episodes: int | None = None, trace_agent: bool = True, render_mode: str | None = None,
                 opponent_p: float = P_TOWARD, copy: bool = True, kernel: str = "auto") -> None:
        if render_mode is not None:
            raise ValueError("GridWarVectorEnv does not render")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        self.num_envs = num_envs
        self.scenario = resolve_scenario(scenario)
        self.backend = backend
        self.sim = make_sim(self.scenario, backend, num_envs, stack_previous, trace=trace_sink is not None,
                            kernel=kernel)
        self.sim.opponent_p = opponent_p
        self.single_observation_space = observation_space(self.scenario, stack_previous)
        self.single_action_space = learner_action_space(self.scenario)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._n = self.scenario.agents_per_team
        self.copy = copy
        self._obs = np.zeros((num_envs, self.single_observation_space.shape[0]), np.float32)  # with copy=False
        self._masker = ActionMasker(self.scenario)
        self._all = np.ones(num_envs, bool)
        self._all.flags.writeable = False  # shared by every `_key` mask that covers all worlds
        # every episode starts from the scenario's start state: one world's reset info serves all
        self._start_info = reset_info(1, self._masks()[:1], self._n == 1)
        self._tracer = None if trace_sink is None else EpisodeTracer(trace_sink, self.scenario, self.sim,
                                                                     limit=trace_episodes,
                                                                     agent_rows=trace_agent)
        self._ready = False

    def reset(self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        seed = _batch_seed(seed)
        super().reset(seed=seed)
        obs = self._observation(reset_sim(self.sim, self._tracer, seed))
        self._ready = True
        return obs, self._with_masks(reset_info(self.num_envs, self._masks(), self._n == 1), self._all)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._ready:
            raise RuntimeError("call reset() before step()")
        res, blue = step_learner(self.sim, self._masker, self._tracer, actions, self.num_envs,
                                 self.single_action_space)
        obs = self._observation(res.obs)
        reward = res.reward[:, RED].copy()  # new arrays: the StepResult's are the simulator's buffers
        terminated, truncated = res.terminated.copy(), res.truncated.copy()
        done = terminated | truncated
        info = step_info(res, self._masks(), self._n == 1, blue)
        if done.any():
            info = self._autoreset(done, obs, info)
        return obs, reward, terminated, truncated, self._with_masks(info, self._all)

    @property
    def records_decisions(self) -> bool:
        """Whether the env records its policy's decisions (a trace sink, `trace_agent`): then `decided` is
        worth calling."""
        return self._tracer is not None and self._tracer.agent_rows

    def decided(self, output: PolicyOutput, acting: np.ndarray, masks: np.ndarray | None = None) -> None:
        """Red's policy output for the next step, recorded as its decisions when traced
        (EpisodeTracer.decided: values [W, N, A] in the scenario's action order, `acting` [W, N])."""
        if self._tracer is not None:
            self._tracer.decided(output, acting, masks)

    def _autoreset(self, done: np.ndarray, obs: np.ndarray, info: dict[str, Any]) -> dict[str, Any]:
        """Reset the finished worlds now; `obs` and `info` switch to their reset values there."""
        final_info = self._with_masks({k: v.copy() for k, v in info.items()}, done)
        final_obs = obs.copy()
        reset_obs = restart_worlds(self.sim, self._tracer, done)[:, RED]
        obs[done] = reset_obs[done]
        for key, value in self._start_info.items():
            info[key][done] = value[0]
        info.update(final_obs=final_obs, _final_obs=done, final_info=final_info, _final_info=done)
        return info

    def _observation(self, both: np.ndarray) -> np.ndarray:
        """Red's observation of the simulator's [W, 2, D]: a new array, or with copy=False the env's buffer."""
        if self.copy:
            return both[:, RED].copy()
        np.copyto(self._obs, both[:, RED])
        return self._obs

    def _masks(self) -> np.ndarray:
        return self._masker.for_sim(self.sim, RED)

    _with_masks = staticmethod(with_masks)

    def close_extras(self, **kwargs: Any) -> None:
        if self._tracer is not None:
            self._tracer.close()
            self._tracer = None
