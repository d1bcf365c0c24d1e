"""StoreSink: the TraceSink (tracelab/envs/sinks.py) that streams RuleSim's trace (tracelab/envs/tracer.py)
into a run of the trace store, through TraceWriter, at the writer's cadence (WRITE_ROWS, WRITE_INTERVAL_S).
A declared world's games are recorded by tracelab/envs/declared/recording.py."""
from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from tracelab.store.agent_rows import AgentRows, Decisions, ObservationName, RewardTerms
from tracelab.store.convert import utc_now
from tracelab.store.writer import WRITE_INTERVAL_S, WRITE_ROWS, TraceWriter

# deferred: the game's scenario module (most of a second) and observation module (numba) load in the methods of a
# game's sink: the store's other users (readers, a declared world's recorder) need not pay


class StoreSink:
    """Writes everything an env streams (program, vocabulary, change rows, steps, episodes) to `writer`.
    The env owns the sink: env.close() closes the writer. Change rows, step records and episode ends are
    kept until WRITE_ROWS step rows wait, WRITE_INTERVAL_S passed or the sink closes (`write_pending`),
    then written after the episode begins kept with them, in that order, so a reader of the run never sees
    an ended episode without its rows. `write_interval_s` None: no write for time's sake (a subclass
    that writes at its own ends); `begin_info`: the begin info of the episodes it begins."""
    write_interval_s: float | None = WRITE_INTERVAL_S
    begin_info: Mapping[str, Any] | None = None

    def __init__(self, writer: TraceWriter) -> None:
        self.writer = writer
        self._engine: Any = None
        self._scenario: Any = None
        self._observation_named = False
        self._agents: list[str] = []
        self._begins: list[dict[str, Any]] = []  # writer.begin_episodes' rows
        self._changes: list[dict[str, np.ndarray]] = []
        self._step_rows = 0
        self._written_at = time.monotonic()
        self._steps: list[tuple[np.ndarray, ...]] = []  # (episode, t, obs, actions, rewards) per env step
        self._ends: list[dict[str, Any]] = []  # writer.end_episodes' rows, ended_at when they ended
        self._agent_rows = AgentRows()  # decisions and reward terms

    def begin_run(self, engine: Any, scenario: Any) -> None:
        self._engine = engine
        self._scenario = scenario
        n = scenario.agents_per_team
        self._agents = [f"{team}-agent-{j + 1}" for team in ("red", "blue") for j in range(n)]
        if engine is not None:
            self.writer.write_engine_program(engine)
        from tracelab.game.scenario import ACTION_NAMES
        offered = list(scenario.action_ids)
        self.writer.write_action_names(ACTION_NAMES, [offered.index(a) if a in offered else None
                                                      for a in range(len(ACTION_NAMES))])

    def begin_episode(self, world: int, episode: int, seed: int | None, scenario: Any) -> None:
        self._begins.append({"episode": int(episode), "world": int(world), "t_start": 0, "seed": seed,
                             "started_at": utc_now(), "info": self.begin_info})

    def changes(self, rows: dict[str, np.ndarray], episode_of_world: np.ndarray,
                t0_of_world: np.ndarray) -> None:
        self._changes.append({k: v for k, v in rows.items() if k != "world_episode"})

    def step(self, world: np.ndarray, episode: np.ndarray, t: np.ndarray, obs: np.ndarray,
             actions: np.ndarray, rewards: np.ndarray) -> None:
        # the env hands over new arrays (sinks.py), so they are kept as they are
        self._steps.append((episode, t, obs, actions, rewards))
        self._step_rows += len(t)
        if self._step_rows >= WRITE_ROWS or (self.write_interval_s is not None
                                             and time.monotonic() - self._written_at >= self.write_interval_s):
            self.write_pending()

    def decisions(self, rows: Decisions) -> None:
        self._agent_rows.decisions(rows)

    def reward_terms(self, rows: RewardTerms) -> None:
        self._agent_rows.reward_terms(rows)

    def end_episode(self, world: int, episode: int, steps: int, outcome: str,
                    rewards: Mapping[str, float]) -> None:
        # episode-local time: the last step's t is the number of steps (t_start is 0)
        self._ends.append({"episode": int(episode), "steps": int(steps), "outcome": outcome, "t_end": int(steps),
                           "reward": float(rewards.get("red", 0.0)), "rewards": dict(rewards),
                           "ended_at": utc_now()})

    def write_pending(self) -> None:
        """Write what is kept: the episode begins, the vocabulary the rows name, the change rows, the step
        records (a row per agent, with its team's observation), the decisions and reward terms, then the
        episode ends."""
        self._written_at = time.monotonic()
        if self._begins:
            begins, self._begins = self._begins, []
            self.writer.begin_episodes(begins)
        if self._changes:
            if self._engine is not None:  # atoms and groundings the rows name must be written first
                self.writer.write_engine_vocabulary(self._engine)
            chunks, self._changes = self._changes, []
            # new arrays, handed over (owned): the writer keeps them without another copy
            self.writer.write_changes(None, {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]},
                                      owned=True)
        if self._steps:
            episode, t, obs, actions, rewards = (np.concatenate(c) for c in zip(*self._steps))
            if self._scenario is not None and not self._observation_named:
                self._write_observation_names(obs.shape[-1])
            self._steps, self._step_rows = [], 0
            m = len(self._agents)  # both teams' agents, red first
            self.writer.write_steps(np.repeat(episode, m), {
                "step": np.repeat(t, m), "t": np.repeat(t, m), "agent": np.tile(self._agents, len(t)),
                "action": actions.reshape(-1), "reward": rewards.reshape(-1),
                "obs": np.repeat(obs, m // 2, axis=1).reshape(len(t) * m, -1)})
        self._agent_rows.write(self.writer)
        if self._ends:
            ends, self._ends = self._ends, []
            self.writer.end_episodes(ends)

    def _write_observation_names(self, size: int) -> None:
        """What the steps' observation entries are, with the first steps (their size says whether the
        observation stacks the previous one)."""
        from tracelab.game.observe import obs_size, team_observation_names
        self._observation_named = True
        names = team_observation_names(self._scenario, size == obs_size(self._scenario, True))
        self.writer.write_observation_names([ObservationName(i, x) for i, x in enumerate(names)])

    def close(self) -> None:
        self.write_pending()
        self.writer.close()
