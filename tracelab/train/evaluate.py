"""Evaluation: a policy plays games against the scripted opponent; outcomes are counted two ways.

- tracelab's: wins, losses, draws and truncations (step limit) as separate counts;
- the method's: its evaluation cut games at 200 steps and counted a cut game as a loss, and counted draws
  and wins by elimination as non-wins. So a method win is a win by capture within 200 steps.

Every world plays a fixed share of the games (not "the first N games to finish", which would favour short
games). A few games can be traced in full into a run (`EvalTrace`): their change rows, steps and
episodes, with begin info `{"kind": "eval", ...}` so `tracelab why` can explain them."""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from tracelab.envs.tracer import outcome_name
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.scenario import Scenario
from tracelab.store.agent_rows import Decisions, RewardTerms
from tracelab.store.sink import StoreSink
from tracelab.store.writer import TraceWriter
from tracelab.train.experiments.stats import spread, wilson
from tracelab.train.env_policy import Policy, may_act

METHOD_CUT = 200  # the method's evaluation cut games at 200 steps


@dataclass
class GameRecord:
    outcome: str       # win | loss | draw | truncated
    steps: int
    reward: float      # red's team return
    actions: int       # decisions of red's agents (agent-steps where an agent could act)
    capture: bool      # a living red agent stands on blue's base at the end


@dataclass
class EvalResult:
    games: int = 0
    wins: int = 0
    losses: int = 0
    draws: int = 0
    truncated: int = 0
    mean_return: float = 0.0
    actions_per_win: float | None = None
    method_wins: int = 0
    method_losses: int = 0       # losses, plus games cut at 200 steps
    method_non_wins: int = 0     # draws and wins by elimination
    method_actions_per_win: float | None = None
    records: list[GameRecord] = field(default_factory=list, repr=False)
    # wall seconds of the traced and of the untraced games (evaluate()): not a result, a cost
    seconds: dict[str, float] = field(default_factory=dict, repr=False, compare=False)

    @property
    def win_rate(self) -> float:
        return self.wins / self.games if self.games else 0.0

    @property
    def method_win_rate(self) -> float:
        return self.method_wins / self.games if self.games else 0.0

    @classmethod
    def of(cls, records: list[GameRecord]) -> "EvalResult":
        r = cls(games=len(records), records=records)
        won, method_won = [], []
        for g in records:
            if g.outcome == "win":
                r.wins += 1
                won.append(g.actions)
            elif g.outcome == "loss":
                r.losses += 1
            elif g.outcome == "draw":
                r.draws += 1
            else:
                r.truncated += 1
            cut = g.steps > METHOD_CUT
            if g.outcome == "win" and g.capture and not cut:
                r.method_wins += 1
                method_won.append(g.actions)
            elif g.outcome in ("loss", "truncated") or cut:
                r.method_losses += 1
            else:
                r.method_non_wins += 1
        r.mean_return = float(np.mean([g.reward for g in records])) if records else 0.0
        r.actions_per_win = float(np.mean(won)) if won else None
        r.method_actions_per_win = float(np.mean(method_won)) if method_won else None
        return r

    def intervals(self) -> dict[str, tuple[float, float]]:
        """95% intervals, as the experiment reports give them: Wilson for the win rates (both countings),
        a t-interval for the mean return (over the games' returns; absent with fewer than two games)."""
        out = {"win_rate": wilson(self.wins, self.games), "method_win_rate": wilson(self.method_wins, self.games)}
        if len(self.records) > 1:
            s = spread([g.reward for g in self.records])
            out["mean_return"] = (s["ci_low"], s["ci_high"])
        return out

    def to_dict(self) -> dict[str, Any]:
        d = {k: v for k, v in asdict(self).items() if k not in ("records", "seconds")}
        d.update(win_rate=self.win_rate, method_win_rate=self.method_win_rate)
        d.update({f"{k}_ci95": list(v) for k, v in self.intervals().items()})
        return d

    def metrics(self, suffix: str = "", prefix: str = "eval/") -> dict[str, float]:
        """The run's `eval/...` metric rows (docs/training.md); `eval_best/` for the kept best policy."""
        m = {"games": self.games, "wins": self.wins, "losses": self.losses, "draws": self.draws,
             "truncated": self.truncated, "win_rate": self.win_rate, "mean_return": self.mean_return,
             "method_win_rate": self.method_win_rate}
        if self.actions_per_win is not None:
            m["actions_per_win"] = self.actions_per_win
        return {f"{prefix}{k}{suffix}": float(v) for k, v in m.items()}


def shares(games: int, worlds: int) -> np.ndarray:
    """Games per world: as even as possible, the first worlds take the remainder."""
    out = np.full(worlds, games // worlds, np.int64)
    out[: games % worlds] += 1
    return out


GameCallback = Callable[[GameRecord], None]


def play_games(env: GridWarVectorEnv, policy: Policy, quota: np.ndarray, seed: int | None,
               on_game: GameCallback | None = None) -> list[GameRecord]:
    """Play `quota[w]` games in world w of `env` (from a reset with `seed`); the games in order of ending,
    each also handed to `on_game` as it ends (a caller's progress).
    Nothing of a step's observation is kept past the next step: `env` may be a copy=False env."""
    sc: Scenario = env.scenario
    n = sc.agents_per_team
    blue_base = np.asarray(sc.blue_base, np.float32)
    obs, info = env.reset(seed=seed)
    left = quota.astype(np.int64).copy()
    ret = np.zeros(env.num_envs)
    decisions = np.zeros(env.num_envs, np.int64)
    records: list[GameRecord] = []
    decide = getattr(env, "records_decisions", False) and hasattr(policy, "decide")  # record the policy's values
    while left.any():
        acting = may_act(sc, env.sim.state)
        masks = info["action_mask"].reshape(env.num_envs, n, -1) if policy.mask or decide else None
        if decide:
            actions, output = policy.decide(obs, acting, masks if policy.mask else None)
            env.decided(output, acting, masks)
        else:
            actions = policy.act(obs, acting, masks)
        decisions += acting.sum(axis=1)
        obs, reward, terminated, truncated, info = env.step(actions[:, 0] if n == 1 else actions)
        ret += reward
        done = terminated | truncated
        if not done.any():
            continue
        final, last = info["final_info"], info["final_obs"]
        for w in np.flatnonzero(done & (left > 0)).tolist():
            pos = last[w, : 2 * n].reshape(n, 2)
            records.append(GameRecord(outcome_name(final["winner"][w], bool(truncated[w])), int(final["t"][w]),
                                      float(ret[w]), int(decisions[w]), bool((pos == blue_base).all(1).any())))
            left[w] -= 1
            if on_game is not None:
                on_game(records[-1])
        ret[done] = 0.0
        decisions[done] = 0
    return records


class EvalSink(StoreSink):
    """Streams chosen episodes of one env into a run it does not own (the env's program is written once,
    at begin_run): `accept(info)` before a reset makes the episodes that reset begins traced ones, under fresh
    run-wide episode ids (`new_id`) with begin
    `info`; later episodes of the env (autoresets) are dropped. close() leaves the writer open.
    An evaluation's rows are written at its end (EvalTrace.play), or every WRITE_ROWS step rows, not
    every WRITE_INTERVAL_S: each write that ends episodes is a publication of the run."""
    write_interval_s = None

    def __init__(self, writer: TraceWriter, new_id: Callable[[], int]) -> None:
        super().__init__(writer)
        self._new_id = new_id
        self._ids: dict[int, int] = {}     # env episode -> run episode, while traced
        self._budget = 0

    def accept(self, info: Mapping[str, Any] | None, episodes: int = 0) -> None:
        """Trace the next `episodes` episodes the env begins, with begin `info`."""
        self.begin_info, self._budget = (None if info is None else dict(info)), episodes

    def begin_episode(self, world: int, episode: int, seed: int | None, scenario: Any) -> None:
        if self.begin_info is None or self._budget <= 0:
            return
        self._budget -= 1
        run_ep = self._new_id()
        self._ids[int(episode)] = run_ep
        super().begin_episode(world, run_ep, seed, scenario)

    def changes(self, rows: dict[str, np.ndarray], episode_of_world: np.ndarray,
                t0_of_world: np.ndarray) -> None:
        keep, run_eps = self._traced(rows["episode"])
        if run_eps.size:
            kept = {k: v[keep] for k, v in rows.items()}
            kept["episode"] = run_eps
            super().changes(kept, episode_of_world, t0_of_world)

    def step(self, world: np.ndarray, episode: np.ndarray, t: np.ndarray, obs: np.ndarray,
             actions: np.ndarray, rewards: np.ndarray) -> None:
        keep, run_eps = self._traced(episode)
        if run_eps.size:
            super().step(world[keep], run_eps, t[keep], obs[keep], actions[keep], rewards[keep])

    def decisions(self, rows: Decisions) -> None:
        keep, run_eps = self._traced(rows.episode)
        if run_eps.size:
            super().decisions(rows.rows(keep, run_eps))

    def reward_terms(self, rows: RewardTerms) -> None:
        keep, run_eps = self._traced(rows.episode)
        if run_eps.size:
            super().reward_terms(rows.rows(keep, run_eps))

    def _traced(self, env_episodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(which rows of `env_episodes` are of traced episodes, those rows' run episode ids), by array
        lookup: a change row each costs too much in Python (thousands a step)."""
        if not self._ids:
            return np.zeros(len(env_episodes), bool), np.zeros(0, np.int64)
        env_ids = np.fromiter(self._ids, np.int64, len(self._ids))
        run_ids = np.fromiter(self._ids.values(), np.int64, len(self._ids))
        order = np.argsort(env_ids)
        env_ids, run_ids = env_ids[order], run_ids[order]
        at = np.minimum(np.searchsorted(env_ids, env_episodes), len(env_ids) - 1)
        keep = env_ids[at] == env_episodes
        return keep, run_ids[at[keep]]

    def end_episode(self, world: int, episode: int, steps: int, outcome: str,
                    rewards: Mapping[str, float]) -> None:
        run_ep = self._ids.pop(int(episode), None)
        if run_ep is not None:
            super().end_episode(world, run_ep, steps, outcome, rewards)

    def close(self) -> None:
        self.write_pending()  # the writer stays open: it is the run's


class EvalTrace:
    """The env whose games are traced into a run: built once per run (one engine, so the run's
    vocabulary and groundings stay one), `games` worlds, one traced game per world per evaluation."""

    def __init__(self, writer: TraceWriter, scenario: Scenario, backend: str, stack_previous: bool,
                 games: int, opponent_p: float, new_id: Callable[[], int], kernel: str = "auto",
                 agent_rows: bool = True) -> None:
        """`agent_rows`: record the policy's decisions and the reward terms too."""
        self.sink = EvalSink(writer, new_id)
        self.games = games
        self.env = GridWarVectorEnv(games, scenario, backend=backend, stack_previous=stack_previous,
                                    trace_sink=self.sink, opponent_p=opponent_p, kernel=kernel, copy=False,
                                    trace_agent=agent_rows)

    def play(self, policy: Policy, seed: int, info: Mapping[str, Any],
             on_game: GameCallback | None = None) -> list[GameRecord]:
        self.sink.accept(info, self.games)  # the reset begins one episode per world
        try:
            return play_games(self.env, policy, np.ones(self.games, np.int64), seed, on_game)
        finally:
            self.sink.accept(None)
            self.sink.write_pending()  # this evaluation's games reach the run now, not with the next

    def close(self) -> None:
        self.env.close()


def evaluate(policy: Policy, scenario: Scenario, *, games: int, backend: str, seed: int, opponent_p: float,
             stack_previous: bool, envs: int = 50, trace: EvalTrace | None = None,
             trace_info: Mapping[str, Any] | None = None, env: GridWarVectorEnv | None = None,
             on_game: GameCallback | None = None) -> EvalResult:
    """`games` games of `policy` (greedy) against the scripted opponent with `opponent_p`. The first
    `trace.games` of them are played (and traced) in `trace`'s env, the rest in `env` (or a new one with
    `envs` worlds). `on_game` is called with each game as it ends."""
    records: list[GameRecord] = []
    seconds: dict[str, float] = {}
    n_traced = min(trace.games, games) if trace is not None else 0
    if n_traced:
        if n_traced < trace.games:
            raise ValueError(f"{games} games cannot fill the {trace.games} traced worlds")
        t0 = time.perf_counter()
        records += trace.play(policy, seed + 1, trace_info or {"kind": "eval"}, on_game)
        seconds["traced"] = time.perf_counter() - t0
    rest = games - n_traced
    if rest:
        t0 = time.perf_counter()
        own = env is None
        if own:
            env = GridWarVectorEnv(min(envs, rest), scenario, backend=backend, stack_previous=stack_previous,
                                   opponent_p=opponent_p)
        try:
            records += play_games(env, policy, shares(rest, env.num_envs), seed, on_game)
        finally:
            if own:
                env.close()
        seconds["untraced"] = time.perf_counter() - t0
    result = EvalResult.of(records)
    result.seconds = seconds
    return result


def evaluate_into(writer: TraceWriter, policy: Policy, scenario: Scenario, *, games: int, backend: str,
                  seed: int, opponent_p: float, metrics_suffix: str | None = None,
                  on_game: GameCallback | None = None) -> EvalResult:
    """`games` games of `policy`, every one traced in full into the run `writer` writes (one world per
    game), which it closes: finished, interrupted (Ctrl-C) or failed. With `metrics_suffix` the figures
    also go into the run's metrics (`eval/...<suffix>`, at step 0)."""
    ids = iter(range(1 << 62))
    status = "failed"
    try:
        trace = EvalTrace(writer, scenario, backend, policy.stack_previous, games, opponent_p, lambda: next(ids))
        try:
            result = evaluate(policy, scenario, games=games, backend=backend, seed=seed, opponent_p=opponent_p,
                              stack_previous=policy.stack_previous, trace=trace,
                              trace_info={"kind": "eval", "opponent_p": opponent_p}, on_game=on_game)
        finally:
            trace.close()
        if metrics_suffix is not None:
            writer.write_metrics(0, result.metrics(metrics_suffix))
        status = "finished"
    except KeyboardInterrupt:
        status = "interrupted"
        raise
    finally:
        writer.close(status=status)
    return result


def comparison_rows(r: EvalResult) -> list[tuple[str, Any, Any]]:
    """(figure, tracelab's counting, the method's counting) for a side-by-side table."""
    def pct(x: float) -> str:
        return f"{100 * x:.1f}%"

    def with_ci(text: str, ci: tuple[float, float] | None, fmt: Callable[[float], str]) -> str:
        return text if ci is None else f"{text} [{fmt(ci[0])}, {fmt(ci[1])}]"
    apw = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
    ci = r.intervals()
    return [("games", r.games, r.games),
            ("wins", r.wins, r.method_wins),
            ("losses", r.losses, r.method_losses),
            ("draws", r.draws, "-"),
            ("truncated (step limit)", r.truncated, "-"),
            ("non-wins (draws, wins by elimination)", "-", r.method_non_wins),
            ("win rate [95% CI]", with_ci(pct(r.win_rate), ci["win_rate"], pct),
             with_ci(pct(r.method_win_rate), ci["method_win_rate"], pct)),
            ("mean return [95% CI]", with_ci(f"{r.mean_return:.1f}", ci.get("mean_return"), lambda v: f"{v:.1f}"),
             "-"),
            ("actions per win", apw(r.actions_per_win), apw(r.method_actions_per_win))]

