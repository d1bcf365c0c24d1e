"""A declared world's games recorded into a run of the trace store: the program (rules, facts, the
board's facts), the vocabulary and groundings, every change row with its cause and grounding, a step row
per env step and one episode per game (seed; steps, return, outcome).

Episode time. Each episode's trace starts at t = 0 with the rows of the world's build (the program's and
the board's facts, and the env's atoms set to [0,0]), replayed for every episode so that its rows alone
rebuild its world, then the rows of the reset's start step (start facts, the drawn start choices), also
at t = 0. Env step k's rows have t = k, unless an `after` random fact took a second engine step in an
earlier step (Taxi's fickle passenger): then `t` is the engine's step count from the start, and the step
rows' `t` says which engine step each env step ended at (`step` is the env step).

The env's facts are external facts (cause `action` in the store's views): the action's facts
(`pressed(right)`) and each drawn random fact (`slip(cw)`), so that `tracelab why` ends at them. Which
predicates are the agent's and which are draws (by name) is in the run's config (`declared_facts`).

Rows are taken from the engine in chunks: when an episode ends (so an episode's rows are all out before
its end is written), every HANDOVER_STEPS steps, when the engine's TRACE_HANDOVER_ROWS rows wait (the engine's buffer stays
bounded), before a reset, and at close; taking them after every step cost more than the engine's step at
one world (docs/benchmarks.md). Everything is written at the pace of store/write_pacing.py: after
WRITE_INTERVAL_S (0.25 s) on a quiet machine, later when the writes would cost more than a tenth of the
stepping thread's CPU (a loaded machine, heavier rows), at most WRITE_MAX_INTERVAL_S (2 s) after the last
write; a live reader sees a game that late at most, plus the writer's own delay. Outcomes:
"terminated", "truncated", or "aborted" (cut short by a reset or close)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from tracelab.board import RUN_CONFIG_KEY, board_config
from tracelab.engine.core import TRACE_HANDOVER_ROWS
from tracelab.envs.declared.spec import WorldSpec
from tracelab.envs.declared.world import DeclaredWorld
from tracelab.store.agent_rows import AgentRows, Decisions, ObservationName, PolicyOutput, RewardTerms
from tracelab.store.convert import utc_now
from tracelab.store.sources import read_sources, source_summaries
from tracelab.store.write_pacing import WRITE_ROWS, WritePacing
from tracelab.store.writer import HANDOVER_STEPS

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from tracelab.store.writer import TraceWriter

CONFIG_KEY = "declared_facts"


def handover_due(engine: Any, steps_waiting: int, episode_ended: bool) -> bool:
    """Whether a recorder takes the engine's trace rows now: an episode ended (its rows are all out
    before its end is written), HANDOVER_STEPS steps wait, or TRACE_HANDOVER_ROWS rows."""
    return episode_ended or steps_waiting >= HANDOVER_STEPS or engine.trace_rows_waiting >= TRACE_HANDOVER_ROWS


def declared_facts(spec: WorldSpec) -> dict[str, Any]:
    """What sets each external fact of a run: the action facts' predicates, and each draw's name with
    its atoms' predicates, and the predicates the env computes ([[clock]], [[nearest]]; the run's config
    under CONFIG_KEY)."""
    actions = sorted({a.pred for per_agent in spec.action_facts for facts in per_agent for a in facts})
    draws = {d.name: sorted({a.pred for value in d.atoms for a in value})
             for d in (*spec.start_choices, *spec.random_facts)}
    computed = sorted({a.pred for c in spec.clocks for a in c.atoms} |
                      {a.pred for n in spec.nearest_facts for per in n.atoms for a in per})
    return {"actions": actions, "draws": draws, **({"computed": computed} if computed else {})}


def spec_sources(spec: WorldSpec) -> list[dict[str, Any]]:
    """The run's `sources` rows of a declared world (tracelab.store.sources): the spec, then each rule file."""
    return read_sources([("spec", str(spec.path)), *(("rules", str(f)) for f in spec.program.files)])


def declared_run_config(spec: WorldSpec, sources: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """What a run of a declared world's games records of it in its config, for its readers: the spec's
    and the rule files' paths, sizes and hashes (their texts go in the run's `sources` table, written by
    DeclaredRecorder), what sets each external fact (CONFIG_KEY), the board the viewers draw. Every
    recorder writes it (DeclaredRecorder), whoever opened the run; `sources`: spec_sources(spec), if read."""
    sources = spec_sources(spec) if sources is None else sources
    return {"sources": source_summaries(sources), CONFIG_KEY: declared_facts(spec),
            RUN_CONFIG_KEY: None if spec.board is None else board_config(spec.board)}


def observation_names(spec: WorldSpec) -> list[ObservationName]:
    """What each entry of a recorded observation (flat_observation) is, named from the spec's observation
    parts: a Discrete space's one number holds every index part (the first the slowest), a
    MultiDiscrete's a number per part; a Box's or Dict's parts put part.width numbers each."""
    parts = spec.parts
    if spec.space == "Discrete":
        sizes = [len(p.atoms) for p in parts]
        divisors = [int(np.prod(sizes[k + 1:], dtype=np.int64)) for k in range(len(parts))]
        return [ObservationName(0, p.name, d, len(p.atoms), [str(a) for a in p.atoms]) for p, d in zip(parts, divisors)]
    if spec.space == "MultiDiscrete":
        return [ObservationName(k, p.name, 1, len(p.atoms), [str(a) for a in p.atoms]) for k, p in enumerate(parts)]
    out: list[ObservationName] = []
    for p in parts:
        at = len(out) and out[-1].position + 1
        if p.read == "index" and p.values is None:
            out.append(ObservationName(at, p.name, 1, len(p.atoms), [str(a) for a in p.atoms]))
        elif p.width == 1:
            out.append(ObservationName(at, p.name))
        elif p.read == "bounds":
            out += [ObservationName(at + 2 * i + b, f"{p.name}[{a}].{end}")
                    for i, a in enumerate(p.atoms) for b, end in enumerate(("lower", "upper"))]
        else:
            out += [ObservationName(at + i, f"{p.name}[{a}]") for i, a in enumerate(p.atoms)]
    return out


def flat_observation(obs: Any) -> np.ndarray:
    """An observation of any of the spec's spaces as one row of numbers (a Dict's parts in order)."""
    if isinstance(obs, dict):
        return np.concatenate([np.asarray(v, np.float32).ravel() for v in obs.values()])
    return np.asarray(obs, np.float32).ravel()


def observation_rows(observations: list[Any]) -> np.ndarray:
    """flat_observation of each observation, stacked: in one conversion unless they are Dicts (a call
    per step cost a toy-text game's recorder ~1 us a step: docs/benchmarks.md)."""
    if observations and not isinstance(observations[0], dict):
        return np.asarray(observations, np.float32).reshape(len(observations), -1)
    return np.stack([flat_observation(o) for o in observations])


class DeclaredRecorder:
    """Records `world`'s episodes into `writer`; the world's engine must trace (DeclaredWorld(trace=True))
    and must not have stepped since it was built. `close()` closes the writer.

    What an episode records is kept and written every WRITE_ROWS steps or when `pacing` says (and at
    close): episode begins, change rows, step rows, then episode ends, so a reader never sees an ended
    episode without its rows. Writing per episode cost more than the toy-text games' steps.

    The run's config gets declared_run_config (the world's external facts, its board, its sources), so a run
opened by gym.make(id, trace_writer=...) reads as one `tracelab play` wrote.

    `episode_ids`: a run the recorder does not own (a training's, whose evaluation games it records):
    episodes take their ids from it, begin with `begin_info`, and close() leaves the writer open.
    `agent_rows` False: no decisions and no reward terms (the world's trace alone)."""

    def __init__(self, world: DeclaredWorld, writer: TraceWriter,
                 episode_ids: Callable[[], int] | None = None, agent_rows: bool = True) -> None:
        eng = world.engine
        if not eng.trace_on.any():
            raise ValueError("the declared world's engine does not trace: build it with trace=True")
        self.world = world
        self.writer = writer
        self.agents = list(world.spec.agents)
        writer.write_engine_program(eng)
        sources = spec_sources(world.spec)
        writer.write_sources(sources)
        # the run's config says what `why`, the replay and the TUI read of the world, however it was opened
        writer.add_config(declared_run_config(world.spec, sources))
        writer.write_action_names(world.spec.action_names)
        writer.write_observation_names(observation_names(world.spec))
        # the agent's half (decisions, reward terms); off: the world's alone (bench eval's baseline)
        self.agent_rows = world.keep_reward_terms = agent_rows
        self._agent_rows = AgentRows()
        # the agent's half of each step kept, one tuple a step (a record, or a tuple per table, costs more):
        # (episode, step, the reward terms' [agent, term] quantities, the actions, (the policy's output for
        # every agent, masks) or None where the policy said nothing)
        self._decided: tuple[PolicyOutput, np.ndarray | None] | None = None
        self._agent_steps: list[tuple[int, int, np.ndarray, Any, tuple[PolicyOutput, np.ndarray | None] | None]] = []
        self._setup = eng.take_trace()  # the build's rows (t = 0), replayed at every episode's start
        self.episode = -1
        self._episode_ids = episode_ids
        self.begin_info: Mapping[str, Any] | None = None  # each episode's begin info, from the next reset on
        self._open = False
        self._t0 = 0  # the engine time of the episode's t = 0
        self._begins: list[dict[str, Any]] = []
        self._changes: list[dict[str, np.ndarray]] = []  # engine rows with t episode-local and `episode`
        # step rows: (episode, step, t, agent index, reward, action, terminated, truncated), and the
        # observation after each of those env steps
        self._steps: list[tuple[int, int, int, int, float, int, bool, bool]] = []
        self._obs: list[np.ndarray] = []
        self._ends: list[dict[str, Any]] = []
        self._clock = (np.zeros(1, np.int64), np.zeros(1, np.int64))  # (t0, episode) for take_trace
        # when the kept records are written (store/write_pacing.py); the writer's last publication is part
        # of a write's cost
        self.pacing = WritePacing(lambda: writer.last_publish_cpu_s)
        self._steps_waiting = 0  # steps whose rows the engine holds
        self._steps_kept = 0     # steps whose records are kept here
        self._length = 0
        self._returns = [0.0] * len(self.agents)
        self._seed: int | None = None

    def before_reset(self) -> None:
        """Before the world resets: the running episode's rows are taken under its own clock, and it ends
        as "aborted"."""
        if self._open:
            self._take_rows()
            self._end("aborted")

    def begin(self, seed: int | None) -> None:
        """After the world's reset: a new episode, its t = 0 the build's rows and the start step's."""
        eng = self.world.engine
        if seed is not None or self.episode < 0:
            self._seed = seed
        self.episode = self.episode + 1 if self._episode_ids is None else self._episode_ids()
        self._open = True
        self._t0 = eng.t - 1
        self._length, self._returns = 0, [0.0] * len(self.agents)
        self._clock = (np.array([self._t0], np.int64), np.array([self.episode], np.int64))
        self._begins.append({"episode": self.episode, "t_start": 0, "seed": self._seed, "started_at": utc_now(),
                             "info": None if self.begin_info is None else dict(self.begin_info)})
        self._changes.append({**self._setup, "episode": np.full(len(self._setup["t"]), self.episode, np.int64)})
        # the start step's rows stay in the engine until the episode's next take, under this same clock
        # (a take per episode fewer: FrozenLake's episodes are ~8 steps)

    def decided(self, output: PolicyOutput, mask: np.ndarray | None = None) -> None:
        """The policy's output (a batch of one decision per agent) and the action mask (one row per
        agent, or None) for the next step: recorded as its decisions."""
        self._decided = (output, mask)

    def stepped(self, actions: Any, rewards: list[float], obs: Any, terminated: bool, truncated: bool) -> None:
        """After an env step: its step rows (one per agent), its reward terms and decisions, and its end
        when it ended."""
        decided, self._decided = self._decided, None
        if not self._open:
            return
        self._length += 1
        t = self.world.engine.t - 1 - self._t0
        if self.agent_rows:  # the output's rows are the agents' (split when written)
            self._agent_steps.append((self.episode, self._length, self.world.last_reward_quantities,
                                      actions if isinstance(actions, (int, np.integer)) else np.array(actions, np.int64),
                                      decided))
        if isinstance(actions, (int, np.integer)):  # one agent (kept short: the toy-text games' case)
            self._returns[0] += rewards[0]
            self._steps.append((self.episode, self._length, t, 0, rewards[0], int(actions), terminated, truncated))
        else:
            for a, act in enumerate(np.asarray(actions, np.int64).tolist()):
                self._returns[a] += rewards[a]
                self._steps.append((self.episode, self._length, t, a, rewards[a], act, terminated, truncated))
        self._obs.append(obs)  # as the env returned it (a new object each step); made numbers when written
        self._steps_waiting += 1
        self._steps_kept += 1
        ended = terminated or truncated
        if handover_due(self.world.engine, self._steps_waiting, ended):
            self._take_rows()
        if ended:
            self._end(self.world.outcome() if terminated else "truncated")
        if self._steps_kept >= WRITE_ROWS or self.pacing.due():
            self.pacing.write(self.write_pending)

    def close(self, status: str = "finished") -> None:
        """The rows still in the engine, the running episode ended as "aborted", all written, the
        writer closed (unless the run is not the recorder's: `episode_ids`)."""
        try:
            if self._open:
                self._take_rows()
                self._end("aborted")
            self.write_pending()
        finally:
            if self._episode_ids is None:
                self.writer.close(status=status)

    def write_pending(self) -> None:
        """Write what is kept: episode begins, the vocabulary the rows name, the change rows, the step
        records (a row per agent), the episode ends."""
        w, eng = self.writer, self.world.engine
        self._steps_kept = 0
        if self._begins:
            begins, self._begins = self._begins, []
            w.begin_episodes(begins)
        if self._changes:
            chunks, self._changes = self._changes, []
            w.write_engine(None, eng, {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]})
        if self._steps:
            episode, step, t, agent, reward, action, term, trunc = (np.array(c) for c in zip(*self._steps))
            w.write_steps(episode, {
                "step": step, "t": t, "agent": [self.agents[a] for a in agent.tolist()], "action": action,
                "reward": reward, "terminated": term, "truncated": trunc,
                "obs": np.repeat(observation_rows(self._obs), len(self.agents), axis=0)})
            self._steps, self._obs = [], []
        self._keep_agent_rows()
        self._agent_rows.write(w)
        if self._ends:
            ends, self._ends = self._ends, []
            w.end_episodes(ends)

    # ----

    def _keep_agent_rows(self) -> None:
        """The kept decisions and reward terms as the store's records (agent_rows)."""
        if not self._agent_steps:
            return
        episode, step, quantities, actions, decided = zip(*self._agent_steps)
        self._agent_steps = []
        # [steps, agents, terms], joined in one concatenate (np.asarray of a list of small arrays is ~3x slower)
        q = np.concatenate(quantities).astype(np.float64, copy=False).reshape(len(quantities), *quantities[0].shape)
        k, m, n_terms = q.shape
        per_step = m * n_terms
        self._agent_rows.reward_terms(RewardTerms(
            np.repeat(episode, per_step), np.repeat(step, per_step), np.tile(np.repeat(np.arange(m), n_terms), k),
            self.agents, np.tile(np.arange(n_terms), k * m), self.world.spec.reward_terms,
            (q * self.world.reward_term_values).reshape(-1), q.reshape(-1)))
        told = [i for i, d in enumerate(decided) if d is not None]  # the steps the policy's output was given for
        if told:
            outputs, masks = zip(*(decided[i] for i in told))
            m, k = len(self.agents), len(told)
            self._agent_rows.decisions(Decisions(
                np.repeat(np.take(episode, told), m), np.repeat(np.take(step, told), m), np.tile(np.arange(m), k),
                self.agents, np.asarray([actions[i] for i in told], np.int64).reshape(-1),
                PolicyOutput.concat(outputs), None if masks[0] is None else np.concatenate(masks).reshape(k * m, -1)))

    def _take_rows(self) -> None:
        """The engine's rows, t counted from the episode's start and labelled with the episode (the
        engine's own localising take: one compiled call, no copy of its buffers)."""
        self._steps_waiting = 0
        rows = self.world.engine.take_trace(self._clock[0], self._clock[1])
        if len(rows["t"]):
            rows["episode"] = rows.pop("world_episode")
            self._changes.append(rows)

    def _end(self, outcome: str) -> None:
        t_end = self.world.engine.t - 1 - self._t0
        self._ends.append({"episode": self.episode, "steps": self._length, "t_end": t_end, "outcome": outcome,
                           "reward": self._returns[0], "rewards": dict(zip(self.agents, self._returns)),
                           "ended_at": utc_now()})
        self._open = False
