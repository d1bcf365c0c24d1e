"""StoreSink: the TraceSink (tracelab/envs/sinks.py) that streams an environment's trace into a run of
the trace store, through TraceWriter."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from tracelab.store.writer import TraceWriter


class StoreSink:
    """Writes everything an env streams (program, vocabulary, change rows, steps, episodes) to `writer`.
    The env owns the sink: env.close() closes the writer."""

    def __init__(self, writer: TraceWriter) -> None:
        self.writer = writer
        self._engine: Any = None
        self._agents: list[str] = []

    def begin_run(self, engine: Any, scenario: Any) -> None:
        self._engine = engine
        n = scenario.agents_per_team
        self._agents = [f"{team}-agent-{j + 1}" for team in ("red", "blue") for j in range(n)]
        if engine is not None:
            self.writer.write_engine_program(engine)

    def begin_episode(self, world: int, episode: int, seed: int | None, scenario: Any) -> None:
        self.writer.begin_episode(int(episode), world=int(world), t_start=0, seed=seed)

    def changes(self, rows: dict[str, np.ndarray], episode_of_world: np.ndarray,
                t0_of_world: np.ndarray) -> None:
        if self._engine is not None:  # atoms and groundings the rows name must be written first
            self.writer.write_vocabulary(self._engine.vocabulary(), self._engine.groundings)
        self.writer.write_changes(None, {k: v for k, v in rows.items() if k != "world_episode"})

    def step(self, world: np.ndarray, episode: np.ndarray, t: np.ndarray, obs: np.ndarray,
             actions: np.ndarray, rewards: np.ndarray) -> None:
        m = len(self._agents)
        for i in range(len(world)):  # one row per agent: its team's observation, its action and reward
            team_obs = np.repeat(obs[i], m // 2, axis=0)
            self.writer.write_steps(int(episode[i]), {
                "step": np.full(m, t[i]), "t": np.full(m, t[i]), "agent": self._agents,
                "action": actions[i].reshape(-1), "reward": rewards[i].reshape(-1), "obs": team_obs})

    def end_episode(self, world: int, episode: int, steps: int, outcome: str,
                    rewards: Mapping[str, float]) -> None:
        # episode-local time: the last step's t is the number of steps (t_start is 0)
        self.writer.end_episode(int(episode), steps=int(steps), outcome=outcome, t_end=int(steps),
                                reward=float(rewards.get("red", 0.0)), rewards=rewards)

    def close(self) -> None:
        self.writer.close()
