"""StoreSink: the TraceSink (tracelab/envs/sinks.py) that streams an environment's trace into a run of
the trace store, through TraceWriter."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from tracelab.store.writer import TraceWriter


# Step records are written in chunks of this many env steps (and at every episode end and at close):
# an Arrow table per step cost more than the simulator's step (docs/benchmarks.md).
STEPS_PER_WRITE = 64


class StoreSink:
    """Writes everything an env streams (program, vocabulary, change rows, steps, episodes) to `writer`.
    The env owns the sink: env.close() closes the writer. Step records are kept until STEPS_PER_WRITE
    steps wait, an episode ends (its steps are written before its end) or the sink closes."""

    def __init__(self, writer: TraceWriter) -> None:
        self.writer = writer
        self._engine: Any = None
        self._agents: list[str] = []
        self._steps: list[tuple[np.ndarray, ...]] = []  # (episode, t, obs, actions, rewards) per env step

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
        # the env hands over new arrays (sinks.py), so they are kept as they are
        self._steps.append((episode, t, obs, actions, rewards))
        if len(self._steps) >= STEPS_PER_WRITE:
            self.write_steps()

    def write_steps(self) -> None:
        """The step records kept so far, as one table: a row per agent, with its team's observation."""
        if not self._steps:
            return
        episode, t, obs, actions, rewards = (np.concatenate(c) for c in zip(*self._steps))
        self._steps = []
        m = len(self._agents)  # both teams' agents, red first
        self.writer.write_steps(np.repeat(episode, m), {
            "step": np.repeat(t, m), "t": np.repeat(t, m), "agent": np.tile(self._agents, len(t)),
            "action": actions.reshape(-1), "reward": rewards.reshape(-1),
            "obs": np.repeat(obs, m // 2, axis=1).reshape(len(t) * m, -1)})

    def end_episode(self, world: int, episode: int, steps: int, outcome: str,
                    rewards: Mapping[str, float]) -> None:
        self.write_steps()  # an ended episode has all its steps
        # episode-local time: the last step's t is the number of steps (t_start is 0)
        self.writer.end_episode(int(episode), steps=int(steps), outcome=outcome, t_end=int(steps),
                                reward=float(rewards.get("red", 0.0)), rewards=rewards)

    def close(self) -> None:
        self.write_steps()
        self.writer.close()
