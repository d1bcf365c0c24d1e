"""The envs' tracer's per-step work as compiled calls (tracelab/envs/tracer.py): the step log, the
returns, and which trace rows belong to which recorded episode.

A traced step's Python cost more than the simulator's own step at one world (docs/benchmarks/history.md, issue
31): five array copies, two sums and two mask tests per step, a dozen numpy calls per hand-over. Here a
step is one compiled call (`StepLog.add`), an episode's begin another (`StepLog.begin`), and the
labelling of a hand-over's trace rows a third (`label_rows`). Each compiles for one signature (the
tracer passes the same array types every time: the simulator's read-only result buffers, its own
arrays), cached on disk like the engine's: ~0.9 s of CPU, spent on a first run in its second process
(`compile_for`; scalar loops: the slice assignments they replace compiled for seconds)."""
from __future__ import annotations

import numpy as np
from numba import njit

from tracelab.game.rulesim import RuleSim
from tracelab.game.state import StepResult
from tracelab.store.agent_rows import Decisions, PolicyOutput


@njit(cache=True)
def _log_step(log_t, log_obs, log_actions, log_rewards, log_events, log_winner, k, t, obs, red, blue,
              agent_reward, reward, unsafe, invalid, hits_made, hits_taken, winner, agent_return, team_return,
              steps, done, recording):  # noqa: ANN001, ANN202 (numba)
    """Row k of the log from one step of every world (with the events its reward terms are made of:
    unsafe, invalid, hits made, hits taken, the winner); the returns (a running total, so the same floats
    as np.add.accumulate over the steps) and steps; returns how many `recording` worlds are `done`."""
    worlds, agents = red.shape
    size = obs.shape[2]
    ended = 0
    for w in range(worlds):
        log_t[k, w] = t[w]
        log_winner[k, w] = winner[w]
        for team in range(2):  # scalar loops: a slice assignment compiles for seconds longer
            for d in range(size):
                log_obs[k, w, team, d] = obs[w, team, d]
        for j in range(agents):
            log_actions[k, w, 0, j] = red[w, j]
            log_actions[k, w, 1, j] = blue[w, j]
            for team in range(2):
                r = agent_reward[w, team, j]
                log_rewards[k, w, team, j] = r
                agent_return[w, team, j] += r
                log_events[k, w, team, j, 0] = unsafe[w, team, j]
                log_events[k, w, team, j, 1] = invalid[w, team, j]
                log_events[k, w, team, j, 2] = hits_made[w, team, j]
                log_events[k, w, team, j, 3] = hits_taken[w, team, j]
        team_return[w, 0] += reward[w, 0]
        team_return[w, 1] += reward[w, 1]
        steps[w] = t[w]
        if done[w] and recording[w]:
            ended += 1
    return ended


@njit(cache=True)
def _episode_of_rows(world, world_episode, episode_of_world, sim_episode_of_world, recording):  # noqa: ANN001, ANN202
    """The env episode of each trace row (-1: not recorded: the simulator's start before the env's first
    episode, or a world whose episode is past the limit or ended) and how many are recorded; -1 as the
    count if a row belongs to a simulator episode the env never began."""
    n = world.shape[0]
    out = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        w = world[i]
        current = sim_episode_of_world[w]
        if world_episode[i] > current:
            return out, -1
        if world_episode[i] == current and recording[w]:
            out[i] = episode_of_world[w]
            kept += 1
        else:
            out[i] = -1
    return out, kept


@njit(cache=True)
def _begin_episodes(worlds, first_id, limit, episode_of_world, sim_episode_of_world, world_episode, recording,
                    agent_return, team_return, steps):  # noqa: ANN001, ANN202 (numba)
    """Episodes first_id, first_id + 1, ... begin in `worlds` (in that order): their ids, the simulator's
    episode numbers (`world_episode`), returns and steps zeroed; those numbered below `limit` are recorded.
    Returns how many are (a prefix of `worlds`: the ids grow)."""
    recorded = 0
    for i in range(worlds.shape[0]):
        w = worlds[i]
        episode = first_id + i
        episode_of_world[w] = episode
        sim_episode_of_world[w] = world_episode[w]
        recording[w] = episode < limit
        recorded += episode < limit
        for team in range(2):
            team_return[w, team] = 0.0
            for j in range(agent_return.shape[2]):
                agent_return[w, team, j] = 0.0
        steps[w] = 0
    return recorded


def label_rows(rows: dict[str, np.ndarray], episode_of_world: np.ndarray, sim_episode_of_world: np.ndarray,
               recording: np.ndarray) -> dict[str, np.ndarray]:
    """RuleSim.take_trace() rows with `episode` (the env's id) added, keeping those of recorded episodes
    (`recording` [W]: the world's current episode is recorded and open; `sim_episode_of_world`: its
    RuleSim.world_episode)."""
    # contiguous int32 / int64 columns (a big hand-over's are strided views): one compiled signature
    world = np.ascontiguousarray(rows["world"], np.int32)
    episode, kept = _episode_of_rows(world, np.ascontiguousarray(rows["world_episode"], np.int64),
                                     episode_of_world, sim_episode_of_world, recording)
    if kept < 0:
        raise RuntimeError("trace rows of a simulator episode the env never began")
    if kept < len(episode):
        keep = episode >= 0
        rows = {name: col[keep] for name, col in rows.items()}
        episode = episode[keep]
    rows["episode"] = episode
    return rows


class StepLog:
    """The step records of up to `capacity` steps, kept in arrays allocated once and handed to the sink
    in one call (a call and five copies per step cost more than the simulator's step at one world).
    The tracer takes the log before any world's episode changes (an end, a begin), so every logged row
    of a world belongs to that world's current episode. Logging a step also keeps each world's returns
    and steps (`agent_return` [W, 2, N], `team_return` [W, 2], `steps` [W]; the tracer zeroes them when
    an episode begins)."""

    def __init__(self, capacity: int, worlds: int, obs_size: int, agents: int) -> None:
        self.capacity, self.k = capacity, 0
        # each the dtype of what is logged (a converting copy costs more)
        self.t = np.empty((capacity, worlds), np.int32)
        self.obs = np.empty((capacity, worlds, 2, obs_size), np.float32)
        self.actions = np.empty((capacity, worlds, 2, agents), np.int64)
        self.rewards = np.empty((capacity, worlds, 2, agents), np.float64)
        self.events = np.empty((capacity, worlds, 2, agents, 4), np.int32)  # unsafe, invalid, hits made, taken
        self.winner = np.empty((capacity, worlds), np.int8)
        self.agent_return = np.zeros((worlds, 2, agents))
        self.team_return = np.zeros((worlds, 2))
        self.steps = np.zeros(worlds, np.int64)
        self._worlds = np.arange(worlds, dtype=np.int64)

    def add(self, res: StepResult, red: np.ndarray, blue: np.ndarray, done: np.ndarray,
            recording: np.ndarray) -> tuple[int, bool]:
        """Log one step of every world (copies: the simulator reuses its arrays). Returns how many
        `recording` worlds are `done`, and whether the log is full."""
        k = self.k
        ended = _log_step(self.t, self.obs, self.actions, self.rewards, self.events, self.winner, k, res.t,
                          res.obs, red, blue, res.agent_reward, res.reward, res.unsafe, res.invalid,
                          res.hits_made, res.hits_taken, res.winner, self.agent_return, self.team_return,
                          self.steps, done, recording)
        self.k = k + 1
        return ended, self.k == self.capacity

    def begin(self, worlds: np.ndarray, first_id: int, limit: int, episode_of_world: np.ndarray,
              sim_episode_of_world: np.ndarray, world_episode: np.ndarray, recording: np.ndarray) -> int:
        """Episodes begin in `worlds` (int64 indices), numbered from `first_id` in that order: their ids
        into `episode_of_world`, `world_episode` (the simulator's count) into `sim_episode_of_world`,
        `recording` set for those numbered below `limit`, returns and steps zeroed. Returns how many are
        recorded (the first ones of `worlds`)."""
        return _begin_episodes(worlds, first_id, limit, episode_of_world, sim_episode_of_world, world_episode,
                               recording, self.agent_return, self.team_return, self.steps)

    def take(self, episode: np.ndarray, recorded: np.ndarray) -> tuple[np.ndarray, ...] | None:
        """Empty the log: (world, episode, t, obs, actions, rewards, events, winner) of the rows of
        `recorded` worlds, new arrays in step order then world order (the first six: the TraceSink.step
        layout; `episode`: each world's), or None."""
        k, self.k = self.k, 0
        if not k:
            return None
        n = np.count_nonzero(recorded)
        if not n:
            return None
        if n == len(recorded):  # every world recorded (the usual case): the log's rows as they lie
            rows = k * n
            world = np.tile(self._worlds, k)
            return (world, episode[world], self.t[:k].reshape(rows).astype(np.int64),
                    self.obs[:k].reshape(rows, 2, -1).copy(), self.actions[:k].reshape(rows, 2, -1).copy(),
                    self.rewards[:k].reshape(rows, 2, -1).copy(),
                    self.events[:k].reshape(rows, *self.events.shape[2:]).copy(), self.winner[:k].reshape(rows).copy())
        keep = np.broadcast_to(recorded, (k, len(recorded)))
        world = np.nonzero(keep)[1]
        return (world, episode[world], self.t[:k][keep].astype(np.int64), self.obs[:k][keep],
                self.actions[:k][keep], self.rewards[:k][keep], self.events[:k][keep], self.winner[:k][keep])


class DecisionLog:
    """The policy's decisions of up to `capacity` steps (EpisodeTracer.decided), kept in arrays allocated
    at the first (when the policy's action count is known) and taken with the step log (so every row of
    a world belongs to its current episode): a record per step cost traced evaluations 70% more CPU."""

    def __init__(self, capacity: int, worlds: int, agents: int) -> None:
        self.capacity, self.worlds, self.agents, self.k = capacity, worlds, agents, 0
        self.t = np.empty((capacity, worlds), np.int64)
        self.acting = np.empty((capacity, worlds, agents), np.bool_)
        self.action = np.empty((capacity, worlds, agents), np.int64)
        self.values: np.ndarray | None = None
        self.mask: np.ndarray | None = None
        self.state_value: np.ndarray | None = None
        self.explored: np.ndarray | None = None
        self.output: PolicyOutput | None = None  # the last one: its kind and ε

    def add(self, t: np.ndarray, output: PolicyOutput, acting: np.ndarray, action: np.ndarray,
            mask: np.ndarray | None) -> bool:
        """Log one step's decisions (values [W, N, A]); returns whether the log is full."""
        k = self.k
        if self.values is None or self.values.shape[3] != output.values.shape[-1]:
            self._allocate(output, mask is not None)
        self.t[k], self.acting[k], self.action[k] = t, acting, action
        self.values[k] = output.values
        if self.mask is not None:
            self.mask[k] = mask if mask is not None else True
        if self.state_value is not None:
            self.state_value[k] = output.state_value
        if self.explored is not None:
            self.explored[k] = output.explored if output.explored is not None else False
        self.output = output
        self.k = k + 1
        return self.k == self.capacity

    def _allocate(self, output: PolicyOutput, masked: bool) -> None:
        shape = (self.capacity, self.worlds, self.agents)
        self.values = np.empty((*shape, output.values.shape[-1]), np.float32)
        self.mask = np.empty((*shape, output.values.shape[-1]), np.bool_) if masked else None
        self.state_value = None if output.state_value is None else np.empty(shape)
        self.explored = None if output.explored is None else np.empty(shape, np.bool_)

    def take(self, episode: np.ndarray, recorded: np.ndarray, agents: np.ndarray, names: list[str]
             ) -> Decisions | None:
        """Empty the log: the decisions of acting agents of `recorded` worlds (`episode`: each world's;
        `agents`: the agents' codes in `names`), in step order, or None."""
        k, self.k = self.k, 0
        if not k or self.values is None:
            return None
        keep = self.acting[:k] & recorded[None, :, None]
        if not keep.any():
            return None
        world = np.nonzero(keep)[1]
        out = self.output
        policy = PolicyOutput(self.values[:k][keep], out.output,
                              None if self.state_value is None else self.state_value[:k][keep],
                              None if self.explored is None else self.explored[:k][keep], out.epsilon)
        return Decisions(episode[world], np.broadcast_to(self.t[:k, :, None], keep.shape)[keep],
                         np.broadcast_to(agents, keep.shape)[keep], names, self.action[:k][keep], policy,
                         None if self.mask is None else self.mask[:k][keep])


def compile_for(sim: RuleSim) -> None:
    """Compile (or load) the kernels above for a RuleSim's argument types without stepping it: a first
    run's second process (tracelab/game/rulesim_warmup.py) does this while the play's process compiles
    the engine, so that the play loads them from numba's cache. Calls each as the tracer does: the
    simulator's result buffers, new int64 actions, a new bool `done`, the tracer's own arrays."""
    res = sim._result  # what its step() returns (the buffers, read-only)
    worlds, agents = sim.n_worlds, sim.scenario.agents_per_team
    log = StepLog(1, worlds, sim.obs_size, agents)
    ids, recording = np.full(worlds, -1, np.int64), np.zeros(worlds, np.bool_)
    log.begin(np.arange(worlds, dtype=np.int64), 0, 1, ids, ids.copy(), sim.world_episode, recording)
    actions = np.zeros((worlds, agents), np.int64)
    log.add(res, actions, actions.copy(), res.terminated | res.truncated, recording)
    label_rows({"world": np.zeros(1, np.int32), "world_episode": np.zeros(1, np.int64)}, ids, ids.copy(),
               recording)
