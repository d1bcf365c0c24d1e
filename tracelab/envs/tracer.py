"""The env side of trace streaming: numbers episodes, labels the simulator's change rows with them, keeps
returns, and calls a TraceSink (conventions in tracelab/envs/sinks.py). Only built when an env has a sink.

RuleSim.take_trace() already counts each row's `t` from its world's episode start and tags it with
`world_episode` (the world's own episode count); here that is mapped to the env's episode id. Rows are
taken in chunks (`handover_due`): after a step in which a recorded episode ended (so an episode's rows
are all out before its end is written), after every HANDOVER_STEPS steps (a live reader of the store sees
rows at most that many steps late, plus the writer's own flush delay), when HANDOVER_ROWS rows wait in the
engine (its buffer stays bounded), before an env reset cuts recorded episodes short (`before_reset`),
and at close. Taking
them after every step cost more than the engine's step at one world (docs/benchmarks.md). Never at the
reset itself: a new episode's start rows are still queued then, and belong to whichever episode is
current in that world when they are taken (RuleSim keeps them for a world reset again before it stepped).
The step records (observations, actions, rewards) are logged in arrays allocated once (StepLog) and
handed over at an episode's end (before it), when HANDOVER_STEPS of them wait, before any episode begins,
and at close.

With `limit` = N only the env's episodes 0..N-1 reach the sink: a world that begins episode N or later
keeps playing (a vector env steps every world) but nothing of it is recorded, so a caller that steps
until those N ended stores exactly N episodes and no "aborted" ones.
Every episode records `seed`: the seed of the env's last reset(seed=...) (None if it had none). The
first episode of each world starts from it; later ones continue the same random stream, so an episode
is reproduced by replaying the run from that reset with the same number of worlds and actions.
"""
from __future__ import annotations

import numpy as np

from tracelab.envs.sinks import TraceSink
from tracelab.envs.step_log import DecisionLog, StepLog, label_rows
from tracelab.game.facts import agent_name
from tracelab.game.refsim import RefSim
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import TEAMS, Rewards, Scenario
from tracelab.game.state import WINNER_BLUE, WINNER_DRAW, WINNER_RED, StepResult
from tracelab.store.agent_rows import PolicyOutput, RewardTerms

# the declared recorder's cadence too (envs/declared/recording.py), kept apart so that RuleSim's env
# loads none of the declared modules
HANDOVER_STEPS = 64
HANDOVER_ROWS = 65_536


def handover_due(sim: RuleSim, steps_waiting: int, episode_ended: bool) -> bool:
    """Whether the simulator's trace rows are to be taken now (the tracer's cadence, module docstring):
    an episode ended in the last step, or HANDOVER_STEPS steps or HANDOVER_ROWS rows wait."""
    return episode_ended or steps_waiting >= HANDOVER_STEPS or sim.engine.trace_rows_waiting >= HANDOVER_ROWS


# GridWar's reward terms (docs/game.md, Rewards), as the store names them
REWARD_TERMS = ("win", "loss", "hit", "got_shot", "step", "unsafe", "invalid")


def reward_terms(weights: Rewards, rewards: np.ndarray, events: np.ndarray,
                 winner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 [K, 2, N, len(REWARD_TERMS)] twice: each agent's reward of K logged world-steps split by term,
    and the quantities those values are of (a term's occurrences: hits counted one by one), from the step's
    events (`events` [K, 2, N, 4]: unsafe, invalid, hits made, hits taken; `winner` [K]) and the scenario's
    reward `weights`; the step term (a valid action's) is what the others leave of the agent's reward
    `rewards` [K, 2, N], so the terms sum to it (tests check that it is 0 or valid_action). The step
    term's occurrences are known only where it is worth something (the log keeps no `acted` flag)."""
    k, _, n, _ = events.shape
    count = np.zeros((k, 2, n, len(REWARD_TERMS)))
    unsafe = events[..., 0] != 0
    count[..., 0] = np.stack([winner == WINNER_RED, winner == WINNER_BLUE], axis=1)[:, :, None]  # won
    count[..., 1] = np.stack([winner == WINNER_BLUE, winner == WINNER_RED], axis=1)[:, :, None]  # lost
    count[..., 2] = events[..., 2]
    count[..., 3] = events[..., 3]
    count[..., 5] = unsafe
    count[..., 6] = ~unsafe & (events[..., 1] != 0)
    out = count * np.array([weights.win, weights.loss, weights.hit_opponent, weights.got_shot, 0.0,
                            weights.unsafe, weights.invalid])
    out[..., 4] = rewards - out.sum(axis=-1)
    if weights.valid_action:
        count[..., 4] = out[..., 4] / weights.valid_action
    return out, count


def outcome_name(winner: int, truncated: bool) -> str:
    """Red's outcome of a finished episode."""
    if truncated:
        return "truncated"
    return {WINNER_RED: "win", WINNER_BLUE: "loss", WINNER_DRAW: "draw"}.get(int(winner), "aborted")


class EpisodeTracer:
    def __init__(self, sink: TraceSink, scenario: Scenario, sim: RuleSim | RefSim,
                 limit: int | None = None, agent_rows: bool = True) -> None:
        """`agent_rows`: record the decisions and reward terms (False: the world's half only)."""
        self.sink = sink
        self.agent_rows = agent_rows
        self.limit = limit
        self._limit = np.iinfo(np.int64).max if limit is None else limit
        self.scenario = scenario
        self.sim = sim
        self._rules = isinstance(sim, RuleSim) and bool(sim.engine.trace_on.any())
        w, n = sim.n_worlds, scenario.agents_per_team
        self.open = np.zeros(w, bool)             # the world's current episode is recorded and not ended
        self.cur_ep = np.full(w, -1, np.int64)   # the env's id of each world's current episode
        self.cur_wep = np.full(w, -1, np.int64)  # and the simulator's world_episode for it
        self._next_episode = 0
        self._steps_waiting = 0                  # steps whose rows the simulator still holds
        self._seed: int | None = None
        # an episode's `rewards`: the teams' returns, then each agent's
        self._return_names = [*TEAMS, *(agent_name(t, j) for t in range(2) for j in range(n))]
        self._log = StepLog(HANDOVER_STEPS, w, sim.obs_size, n)
        self._agent_names = [agent_name(t, j) for t in range(2) for j in range(n)]  # red's first
        self._decided: tuple[PolicyOutput, np.ndarray, np.ndarray | None] | None = None
        self._decisions = DecisionLog(HANDOVER_STEPS, w, n)
        self._red_codes = np.arange(n)
        # each world's returns and steps, kept by the log's step call
        self.steps, self.agent_return, self.team_return = self._log.steps, self._log.agent_return, \
            self._log.team_return
        sink.begin_run(sim.engine if isinstance(sim, RuleSim) else None, scenario)

    def begin(self, worlds: np.ndarray, seed: int | None) -> None:
        """Episodes start in `worlds` (indices), which the simulator has just reset; `seed` is the
        reset's seed (None for an autoreset: the episode continues the last seeded stream)."""
        worlds = np.asarray(worlds, np.int64)
        if seed is not None or self._next_episode == 0:
            self._seed = seed
        self._hand_steps()  # the logged steps belong to the episodes before (StepLog)
        if np.count_nonzero(self.open[worlds]):
            for w in worlds[self.open[worlds]].tolist():
                self._end(w, "aborted")
        first = self._next_episode
        self._next_episode += len(worlds)
        # a RefSim has no episode count of its own: the tracer's is copied onto itself
        recorded = self._log.begin(worlds, first, self._limit, self.cur_ep, self.cur_wep,
                                   self.sim.world_episode if self._rules else self.cur_wep, self.open)
        for i, w in enumerate(worlds[:recorded].tolist()):
            self.sink.begin_episode(w, first + i, self._seed, self.scenario)

    def before_reset(self) -> None:
        """Before an env reset (not an autoreset): the rows of steps not handed over yet, so that the
        episodes it cuts short have all their rows out before their end is written. A world that has not
        stepped since its start holds only start rows, which stay for the episode that begins."""
        if self._steps_waiting:
            self._flush()
        self._hand_steps()

    def decided(self, output: PolicyOutput, acting: np.ndarray, masks: np.ndarray | None = None) -> None:
        """Red's policy output for the coming step: `output`'s rows [W, N, ...] (values [W, N, A] in the
        scenario's action order), `acting` [W, N] which agents chose, `masks` [W, N, A] the allowed
        actions (None: none). Recorded as the decisions of the next `stepped`."""
        self._decided = (output, acting, masks)

    def stepped(self, res: StepResult, red: np.ndarray, blue: np.ndarray, done: np.ndarray | None = None
                ) -> None:
        """After a step of every world (before any autoreset), with both teams' actions (spec ids,
        [W, N]) and, if the caller has it, `done` = res.terminated | res.truncated: its step record is
        logged (with the decisions `decided` before it); its rows and the logged steps are handed over
        when due; episode ends."""
        self._steps_waiting += 1
        decisions_full = False
        if self._decided is not None:
            output, acting, masks = self._decided
            self._decided = None
            if self.agent_rows:
                decisions_full = self._decisions.add(res.t, output, acting, red, masks)
        if done is None:
            done = res.terminated | res.truncated
        ended, full = self._log.add(res, red, blue, done, self.open)
        full = full or decisions_full
        if self._rules and handover_due(self.sim, self._steps_waiting, ended > 0):
            self._flush()
        if ended or full:
            self._hand_steps()
            if ended:
                for w in np.flatnonzero(done & self.open).tolist():
                    self._end(w, outcome_name(res.winner[w], bool(res.truncated[w])))

    def close(self) -> None:
        self._flush()
        self._hand_steps()
        for w in np.flatnonzero(self.open).tolist():
            self._end(w, "aborted")
        self.sink.close()

    def _hand_steps(self) -> None:
        """The logged step records of recorded episodes to the sink, in step order, and their reward
        terms."""
        decisions = self._decisions.take(self.cur_ep, self.open, self._red_codes, self._agent_names)
        if decisions is not None:
            self.sink.decisions(decisions)
        steps = self._log.take(self.cur_ep, self.open)
        if steps is None:
            return
        world, episode, t, obs, actions, rewards, events, winner = steps
        self.sink.step(world, episode, t, obs, actions, rewards)
        if not self.agent_rows:
            return
        terms, quantities = reward_terms(self.scenario.rewards, rewards, events, winner)  # [K, 2, N, T]
        k, m, n_terms = len(t), len(self._agent_names), len(REWARD_TERMS)
        per_row = m * n_terms
        self.sink.reward_terms(RewardTerms(
            np.repeat(episode, per_row), np.repeat(t, per_row), np.tile(np.repeat(np.arange(m), n_terms), k),
            self._agent_names, np.tile(np.arange(n_terms), k * m), REWARD_TERMS, terms.reshape(-1),
            quantities.reshape(-1)))

    def _flush(self) -> None:
        if not self._rules:
            return
        self._steps_waiting = 0
        rows = self.sim.take_trace()
        if not len(rows["t"]):
            return
        rows = label_rows(rows, self.cur_ep, self.cur_wep, self.open)
        if len(rows["episode"]):
            self.sink.changes(rows, self.cur_ep.copy(), self.sim.episode_start.copy())

    def _end(self, w: int, outcome: str) -> None:
        rewards = dict(zip(self._return_names, self.team_return[w].tolist() + self.agent_return[w].ravel().tolist()))
        self.sink.end_episode(w, int(self.cur_ep[w]), int(self.steps[w]), outcome, rewards)
        self.open[w] = False
