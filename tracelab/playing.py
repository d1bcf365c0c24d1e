"""Playing games of the rule-driven simulator, as `tracelab play` does: red by a simple policy (random,
the scripted base policy) or a trained one, blue by the scripted opponent, every episode traced into a
TraceSink (a run of the store) when one is given.

`Games` steps the simulator and the envs' tracer (tracelab/envs/tracer.py) directly, with the vector
env's same-step autoreset (tracelab.envs.common.restart_worlds) and episode numbering, so a run is the one
GridWarVectorEnv would record for the same seed and worlds; it builds no gymnasium infos, masks or
observation copies that no policy reads (they cost more than the simulator's step: docs/benchmarks.md).

Library code: nothing here prints (the command does)."""
from __future__ import annotations

from typing import Any

import numpy as np

from tracelab.envs.common import ActionMasker, make_sim, reset_sim, restart_worlds
from tracelab.envs.sinks import TraceSink
from tracelab.envs.tracer import EpisodeTracer
from tracelab.game.opponent import P_TOWARD
from tracelab.game.scenario import NOTHING, RED, Scenario

OUTCOMES = {0: "win", 1: "loss", 2: "draw"}  # from red's side, by WINNER_RED / BLUE / DRAW
POLICIES = ("random", "scripted")  # red's built-in policies


def _scripted_ids(scenario: Scenario) -> list[int]:
    """The spec ids the scripted policy can play (tracelab.game.opponent): moves, nothing, the scenario's
    own actions, and shots in an advanced game."""
    return sorted({0, 1, 2, 3, NOTHING, *scenario.action_ids, *((4, 5, 6, 7) if scenario.advanced else ())})


class Games:
    """Exactly `episodes` episodes in `worlds` worlds (at most `episodes`). Episodes are numbered in the
    order they begin; those numbered past the last one asked for are played (every world steps) but
    neither counted nor recorded (the tracer's limit), so a run holds exactly the episodes asked for, none
    cut short. Building it resets every world; call `step()` until `done`. `trained`: a loaded policy
    (tracelab.train.env_policy), else red plays `policy`. `kernel`: the engine's (Engine)."""

    def __init__(self, scenario: Scenario, episodes: int, *, worlds: int = 1, policy: str = "scripted",
                 trained: Any = None, seed: int = 0, sink: TraceSink | None = None, kernel: str = "auto",
                 opponent_p: float | None = None) -> None:
        if trained is None and policy not in POLICIES:
            raise ValueError(f"policy {policy!r}: expected one of {POLICIES} or a trained policy")
        self.scenario, self.episodes = scenario, episodes
        self.worlds = min(worlds, episodes)
        self.policy, self.trained = policy, trained
        self.rng = np.random.default_rng(seed)
        self.sim = make_sim(scenario, "rules", self.worlds, trained is not None and trained.stack_previous,
                            trace=sink is not None, kernel=kernel)
        self.sim.opponent_p = P_TOWARD if opponent_p is None else opponent_p
        self.tracer = None if sink is None else EpisodeTracer(sink, scenario, self.sim, limit=episodes)
        self._masker = ActionMasker(scenario)
        ids = self._masker.ids
        index_of = {a: i for i, a in enumerate(scenario.action_ids)}
        # the scripted policy's spec ids as red plays them: an action the scenario does not offer is its
        # first (None: it offers all the policy plays, the usual case)
        scripted_red = ids[[index_of.get(a, 0) for a in range(9)]]
        self._scripted_red = None if (scripted_red == np.arange(9))[_scripted_ids(scenario)].all() else scripted_red
        self.finished: dict[int, dict[str, Any]] = {}  # episode -> steps, outcome, return
        self.wins = 0  # of the finished episodes
        self.episode_of_world = np.arange(self.worlds)
        self._next_episode = self.worlds
        self._playing = self.worlds  # worlds playing an asked-for episode
        self._obs = reset_sim(self.sim, self.tracer, seed)
        # each world's team returns over its episode: the tracer keeps them when there is one (the same
        # sums); all of StepResult.reward (a strided add costs more)
        self._team_returns = np.zeros((self.worlds, 2)) if self.tracer is None else self.tracer.team_return

    @property
    def done(self) -> bool:
        return len(self.finished) >= self.episodes

    def step(self) -> tuple[int, int]:
        """Step every world once; returns (steps of asked-for episodes, how many of them ended)."""
        sim = self.sim
        red = self._red_actions()
        blue = sim.scripted_actions("blue")
        res = sim.step(red, blue)
        ended_worlds = res.terminated | res.truncated
        if self.tracer is not None:
            self.tracer.stepped(res, red, blue, ended_worlds)
        played = self._playing
        if self.tracer is None:
            self._team_returns += res.reward
        self._obs = res.obs
        if not np.count_nonzero(ended_worlds):
            return played, 0
        done = np.flatnonzero(ended_worlds)
        ended = 0
        for w in done.tolist():
            if self.episode_of_world[w] < self.episodes:
                outcome = OUTCOMES.get(int(res.winner[w]), "truncated")
                self.finished[int(self.episode_of_world[w])] = {
                    "steps": int(res.t[w]), "outcome": outcome, "return": float(self._team_returns[w, RED])}
                self.wins += outcome == "win"
                ended += 1
        if self.tracer is None:
            self._team_returns[done] = 0.0  # (the tracer zeroes its own when the episodes begin)
        self._obs = restart_worlds(sim, self.tracer, ended_worlds)
        self.episode_of_world[done] = self._next_episode + np.arange(len(done))  # as the tracer numbers them
        self._next_episode += len(done)
        self._playing = int(np.count_nonzero(self.episode_of_world < self.episodes))
        return played, ended

    def _red_actions(self) -> np.ndarray:
        """Red's spec action ids [W, N]."""
        if self.trained is not None:
            from tracelab.train.env_policy import may_act
            n = self.scenario.agents_per_team
            obs = np.ascontiguousarray(self._obs[:, RED])
            traced = self.tracer is not None
            masks = (self._masker.for_sim(self.sim, RED).reshape(self.worlds, n, -1)
                     if self.trained.mask or traced else None)
            acting = may_act(self.scenario, self.sim.state)
            if traced:  # the policy's values recorded as the step's decisions
                idx, output = self.trained.decide(obs, acting, masks if self.trained.mask else None)
                self.tracer.decided(output, acting, masks)
            else:
                idx = self.trained.act(obs, acting, masks)
            return self._masker.ids[np.asarray(idx, np.int64).reshape(self.worlds, n)]
        if self.policy == "scripted":
            red = self.sim.scripted_actions("red")
            return red if self._scripted_red is None else self._scripted_red[red]
        idx = self.rng.integers(0, self.scenario.n_actions, size=(self.worlds, self.scenario.agents_per_team))
        return self._masker.ids[idx]

    def close(self) -> None:
        """Hand the last rows to the sink and close it (the env's tracer owns the sink)."""
        if self.tracer is not None:
            self.tracer.close()
            self.tracer = None
