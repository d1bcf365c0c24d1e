"""Where an environment streams its trace: the `TraceSink` protocol, and `MemorySink` (keeps everything).

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
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

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


def _concat(chunks: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    if not chunks:
        return {}
    return {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}


@dataclass
class MemorySink:
    """A TraceSink that keeps every call in lists (tests, notebooks, small runs)."""
    runs: list[tuple[Any, Any]] = field(default_factory=list)        # (engine, scenario)
    begun: list[dict[str, Any]] = field(default_factory=list)        # world, episode, seed
    change_chunks: list[dict[str, np.ndarray]] = field(default_factory=list)
    step_chunks: list[dict[str, np.ndarray]] = field(default_factory=list)
    ended: list[dict[str, Any]] = field(default_factory=list)        # world, episode, steps, outcome, rewards
    decision_rows: list["Decisions"] = field(default_factory=list)
    reward_term_rows: list["RewardTerms"] = field(default_factory=list)
    closed: bool = False

    def begin_run(self, engine: "Engine | None", scenario: "Scenario") -> None:
        self.runs.append((engine, scenario))

    def begin_episode(self, world: int, episode: int, seed: int | None, scenario: "Scenario") -> None:
        self.begun.append({"world": world, "episode": episode, "seed": seed})

    def changes(self, rows: dict[str, np.ndarray], episode_of_world: np.ndarray,
                t0_of_world: np.ndarray) -> None:
        self.change_chunks.append(rows)

    def step(self, world: np.ndarray, episode: np.ndarray, t: np.ndarray, obs: np.ndarray,
             actions: np.ndarray, rewards: np.ndarray) -> None:
        self.step_chunks.append({"world": world, "episode": episode, "t": t, "obs": obs,
                                 "actions": actions, "rewards": rewards})

    def decisions(self, rows: "Decisions") -> None:
        self.decision_rows.append(rows)

    def reward_terms(self, rows: "RewardTerms") -> None:
        self.reward_term_rows.append(rows)

    def end_episode(self, world: int, episode: int, steps: int, outcome: str,
                    rewards: Mapping[str, float]) -> None:
        self.ended.append({"world": world, "episode": episode, "steps": steps, "outcome": outcome,
                           "rewards": dict(rewards)})

    def close(self) -> None:
        self.closed = True

    # ---- reading back ----
    def rows(self, episode: int | None = None) -> dict[str, np.ndarray]:
        """All change rows in arrival order (or one episode's), as one dict of columns."""
        out = _concat(self.change_chunks)
        if episode is None or not out:
            return out
        keep = out["episode"] == episode
        return {k: v[keep] for k, v in out.items()}

    def steps(self, episode: int | None = None) -> dict[str, np.ndarray]:
        """All step records (or one episode's), one row per world and step."""
        out = _concat(self.step_chunks)
        if episode is None or not out:
            return out
        keep = out["episode"] == episode
        return {k: v[keep] for k, v in out.items()}
