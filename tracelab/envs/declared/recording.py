"""A declared world's games recorded into a run of the trace store, as GridWar's envs record theirs
(tracelab/envs/tracer.py, tracelab/store/sink.py): the program (rules, facts, the board's facts), the
vocabulary and groundings, every change row with its cause and grounding, a step row per env step and
one episode per game (seed; steps, return, outcome).

Episode time. Each episode's trace starts at t = 0 with the rows of the world's build (the program's and
the board's facts, and the env's atoms set to [0,0]), replayed for every episode so that its rows alone
rebuild its world, then the rows of the reset's start step (start facts, the drawn start choices), also
at t = 0. Env step k's rows have t = k, unless an `after` random fact took a second engine step in an
earlier step (Taxi's fickle passenger): then `t` is the engine's step count from the start, and the step
rows' `t` says which engine step each env step ended at (`step` is the env step).

The env's facts are external facts (cause `action` in the store's views): the action's facts
(`pressed(right)`) and each drawn random fact (`slip(cw)`), so that `tracelab why` ends at them. Which
predicates are the agent's and which are draws (by name) is in the run's config (`declared_facts`).

Rows are taken from the engine in chunks (tracelab.envs.tracer's cadence): when an episode ends, every
HANDOVER_STEPS steps, when HANDOVER_ROWS rows wait, before a reset, and at close. Outcomes:
"terminated", "truncated", or "aborted" (cut short by a reset or close)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from tracelab.envs.declared.spec import WorldSpec
from tracelab.envs.declared.world import DeclaredWorld
from tracelab.envs.tracer import HANDOVER_ROWS, HANDOVER_STEPS

if TYPE_CHECKING:
    from tracelab.store.writer import TraceWriter

CONFIG_KEY = "declared_facts"


def declared_facts(spec: WorldSpec) -> dict[str, Any]:
    """What sets each external fact of a run: the action facts' predicates, and each draw's name with
    its atoms' predicates (the run's config under CONFIG_KEY)."""
    actions = sorted({a.pred for per_agent in spec.action_facts for facts in per_agent for a in facts})
    draws = {d.name: sorted({a.pred for value in d.atoms for a in value})
             for d in (*spec.start_choices, *spec.random_facts)}
    return {"actions": actions, "draws": draws}


def flat_observation(obs: Any) -> np.ndarray:
    """An observation of any of the spec's spaces as one row of numbers (a Dict's parts in order)."""
    if isinstance(obs, dict):
        return np.concatenate([np.asarray(v, np.float32).ravel() for v in obs.values()])
    return np.asarray(obs, np.float32).ravel()


class DeclaredRecorder:
    """Records `world`'s episodes into `writer`; the world's engine must trace (DeclaredWorld(trace=True))
    and must not have stepped since it was built. `close()` closes the writer."""

    def __init__(self, world: DeclaredWorld, writer: TraceWriter) -> None:
        eng = world.engine
        if not eng.trace_on.any():
            raise ValueError("the declared world's engine does not trace: build it with trace=True")
        self.world = world
        self.writer = writer
        self.agents = list(world.spec.agents)
        writer.write_engine_program(eng)
        self._setup = eng.take_trace()  # the build's rows (t = 0), replayed at every episode's start
        self.episode = -1
        self._open = False
        self._t0 = 0  # the engine time of the episode's t = 0
        # step rows not written yet: (step, t, agent index, reward, action, terminated, truncated), and
        # the observation after each of those env steps
        self._steps: list[tuple[int, int, int, float, int, bool, bool]] = []
        self._obs: list[np.ndarray] = []
        self._steps_waiting = 0
        self._length = 0
        self._returns = [0.0] * len(self.agents)
        self._seed: int | None = None

    def before_reset(self) -> None:
        """Before the world resets: the running episode's rows go out under its own clock, and it ends
        as "aborted"."""
        if self._open:
            self._take_rows()
            self._end("aborted")

    def begin(self, seed: int | None) -> None:
        """After the world's reset: a new episode, its t = 0 the build's rows and the start step's."""
        eng = self.world.engine
        if seed is not None or self.episode < 0:
            self._seed = seed
        self.episode += 1
        self._open = True
        self._t0 = eng.t - 1
        self._length, self._returns = 0, [0.0] * len(self.agents)
        self.writer.begin_episode(self.episode, t_start=0, seed=self._seed)
        self._write_rows(self._setup)
        self._take_rows()

    def stepped(self, actions: Any, rewards: list[float], obs: Any, terminated: bool, truncated: bool) -> None:
        """After an env step: its step rows (one per agent), and its end when it ended."""
        if not self._open:
            return
        self._length += 1
        t = self.world.engine.t - 1 - self._t0
        acts = np.atleast_1d(np.asarray(actions, np.int64))
        for a in range(len(self.agents)):
            self._returns[a] += float(rewards[a])
            self._steps.append((self._length, t, a, float(rewards[a]), int(acts[a]), terminated, truncated))
        self._obs.append(flat_observation(obs))
        self._steps_waiting += 1
        ended = terminated or truncated
        if ended or self._steps_waiting >= HANDOVER_STEPS or \
                self.world.engine.trace_rows_waiting >= HANDOVER_ROWS:
            self._take_rows()
        if ended:
            self._end("terminated" if terminated else "truncated")

    def close(self, status: str = "finished") -> None:
        """The rows still in the engine, the running episode ended as "aborted", the writer closed."""
        if self._open:
            self._take_rows()
            self._end("aborted")
        self.writer.close(status=status)

    # ----

    def _take_rows(self) -> None:
        self._steps_waiting = 0
        rows = self.world.engine.take_trace()
        if len(rows["t"]):
            rows["t"] = (rows["t"] - self._t0).astype(np.int32)
            self._write_rows(rows)
        self._write_steps()

    def _write_rows(self, rows: dict[str, np.ndarray]) -> None:
        self.writer.write_engine(self.episode, self.world.engine, dict(rows))

    def _write_steps(self) -> None:
        if not self._steps:
            return
        step, t, agent, reward, action, term, trunc = zip(*self._steps)
        obs = np.stack(self._obs)
        n_agents = len(self.agents)
        self.writer.write_steps(self.episode, {
            "step": np.array(step), "t": np.array(t), "agent": [self.agents[a] for a in agent],
            "action": np.array(action), "reward": np.array(reward), "terminated": np.array(term),
            "truncated": np.array(trunc), "obs": np.repeat(obs, n_agents, axis=0)})
        self._steps, self._obs = [], []

    def _end(self, outcome: str) -> None:
        self._write_steps()
        t_end = self.world.engine.t - 1 - self._t0
        self.writer.end_episode(self.episode, steps=self._length, t_end=t_end, outcome=outcome,
                                reward=self._returns[0], rewards=dict(zip(self.agents, self._returns)))
        self._open = False
