"""Where RuleSim's batched env (vector_env.py) streams its trace: the `TraceSink` protocol (the store's is
tracelab.store.sink.StoreSink).

An env given `trace_sink=` calls, in this order:

    begin_run(engine, scenario)                       once, when the env is built
    begin_episode(world, episode, seed, scenario)     when a world starts an episode (reset / autoreset)
    changes(rows, episode_of_world, t0_of_world)      the episode's start rows (t = 0), then each step's
    decisions(rows)                                   the policy's decisions of a step (if it gave them)
    step(world, episode, t, obs, actions, rewards)    after steps, batched over the worlds and steps
    reward_terms(rows)                                those steps' rewards by term, after them
    end_episode(world, episode, steps, outcome, rewards)
    close()                                           from env.close(); the env owns its sink

Conventions:
- `episode` ids are unique within one env, counted from 0 in the order episodes begin.
- Engine time counts globally; a world whose episode started at engine time T0 is at episode step
  t - T0 (RuleSim.take_trace() does this). Step k's rows have t == k, the k-th `StepResult.t`. The
  episode's first rows (t = 0) are the engine's start-of-game rows (scenario facts, from no knowledge),
  replayed by RuleSim for every episode, so each episode's rows alone rebuild its world.
- `changes` rows are Engine.take_trace() columns (docs/engine-api.md) with `t` made episode-local, plus
  `episode` (int64, the env's id) and RuleSim's `world_episode` (that world's own episode count).
  `episode_of_world` is the env episode each world is playing, `t0_of_world` the engine time of its
  episode's t = 0. Only the rules backend has change rows; they may arrive with the first step's.
- `step` arguments are arrays with one row per world and step (in step order, then world order; the
  tracer hands a chunk of steps over with the change rows, and always before the end of their episode):
  world, episode, t int64 [K];
  obs float32 [K, 2, D] (both teams' observations after the step); actions int64 [K, 2, N] (spec ids);
  rewards float64 [K, 2, N] (`StepResult.agent_reward`).
- `decisions` and `reward_terms` rows (tracelab.store.agent_rows.Decisions, RewardTerms) carry the env's
  episode ids, and `step` as the step rows' `t`; decisions come only from a caller that told the env its
  policy's output (EpisodeTracer.decided); reward terms sum to each agent's `rewards` entry.
- `outcome` is red's (the learner's): "win", "loss", "draw", "truncated", or "aborted" for an episode
  cut short by a reset or close (a vector env's `trace_episodes=N` records none of those past N).
- `seed` is the seed of the env's last reset(seed=...) for every episode (see tracelab/envs/tracer.py).
  `rewards` maps "red", "blue" (team returns) and every agent name
  (`red-agent-1`, ...) to its return over the episode.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from tracelab.engine import Engine
    from tracelab.store.agent_rows import Decisions, RewardTerms

    from tracelab.game.scenario import Scenario


@runtime_checkable
class TraceSink(Protocol):
    def begin_run(self, engine: "Engine | None", scenario: "Scenario") -> None: ...

    def begin_episode(self, world: int, episode: int, seed: int | None, scenario: "Scenario") -> None: ...

    def changes(self, rows: dict[str, np.ndarray], episode_of_world: np.ndarray,
                t0_of_world: np.ndarray) -> None: ...

    def step(self, world: np.ndarray, episode: np.ndarray, t: np.ndarray, obs: np.ndarray,
             actions: np.ndarray, rewards: np.ndarray) -> None: ...

    def decisions(self, rows: "Decisions") -> None: ...

    def reward_terms(self, rows: "RewardTerms") -> None: ...

    def end_episode(self, world: int, episode: int, steps: int, outcome: str,
                    rewards: Mapping[str, float]) -> None: ...

    def close(self) -> None: ...
