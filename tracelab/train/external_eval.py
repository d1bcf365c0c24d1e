"""Evaluations of a policy another library trains (Stable-Baselines3, ...), as tracelab's trainer makes its
own: greedy games every so many steps, the first few of each evaluation traced in full into the training's
run (begin info `{"kind": "eval", "train_step": N, "eval_round": K, "params": {...}}`: eval_info), so
`tracelab why`, `replay` and the TUI's evaluation games work on them, and the figures as the run's `eval/...`
metrics.

The envs traced are the rules-declared worlds (a registered id such as tracelab/FrozenLake-v1 or
tracelab/FrozenLake-v1, or a spec file): a traced DeclaredEnv records them, as `tracelab play --env --run`
does. The policy is a function from a batch of observations to a batch of actions (`Act`): the library's
greedy prediction."""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

import tracelab.envs  # noqa: F401  (registers the declared worlds' ids)
from tracelab.errors import UserError
from tracelab.store.agent_rows import PolicyOutput
from tracelab.store.writer import TraceWriter
from tracelab.train.env_policy import (EVAL_STEP_CAP, EnvEvalResult, declares_outcomes, make_vector_env,
                                       one_env_actor, play_env_games, team_env_actor)
from tracelab.envs.declared.env_source import EnvSource
from tracelab.train.env_source import team_spec
from tracelab.train.rngs import eval_seed
from tracelab.world_extras import evaluation_env

# deferred: the declared world's recording and TeamEnv load the engine (numba), which a gymnasium env's
# training does not need

Act = Callable[[Any], np.ndarray]  # a batch of observations -> the batch's (greedy) actions
NewId = Callable[[], int]          # the run's next free episode id


@dataclass(frozen=True)
class EvalSettings:
    """When and how a training is evaluated (tracelab train's --eval-every, --eval-games, ... alike)."""
    every: int = 10_000      # training steps between evaluations (0: only at the end)
    games: int = 50          # games per evaluation
    traced: int = 5          # of which traced in full into the run
    envs: int = 16           # worlds stepped together for the untraced games
    level: float = 0.3       # the evaluation's level, where a world's registration gives it one (the war game:
    #                          its scripted opponent's probability of a move towards red's base)
    seed: int = 0            # evaluation seeds: eval_seed(seed, round), as tracelab train's

    def __post_init__(self) -> None:
        if self.every < 0 or self.games < 1 or self.traced < 0 or self.envs < 1:
            raise ValueError(f"evaluation settings: every >= 0, games >= 1, traced >= 0, envs >= 1; got {self}")
        if not 0.0 <= self.level <= 1.0:
            raise ValueError(f"evaluation settings: level must lie in [0, 1], got {self.level}")


class Evaluator(Protocol):
    def run(self, act: Act, step: int, round_no: int) -> dict[str, float]:
        """One evaluation at training step `step`; returns its `eval/...` metrics."""

    def close(self) -> None: ...


class EvalTarget(Protocol):
    """An env another library trains on, as tracelab records and evaluates it."""
    name: str

    def run_meta(self) -> dict[str, Any]:
        """The run's meta.json fields that describe the env (scenario, board, rule files, config)."""

    def outcome(self, info: Mapping[str, Any], terminated: bool, truncated: bool) -> str:
        """A training episode's outcome from its last step."""

    def evaluator(self, writer: TraceWriter, new_id: NewId, settings: EvalSettings) -> Evaluator: ...


def eval_info(source: EnvSource, step: int | None = None, round_no: int | None = None) -> dict[str, Any]:
    """An evaluation game's begin info (docs/training.md, "What is logged, and where"): the world's params it
    is played with (`source`'s, as its spec reads them), and a training's step and round (`tracelab eval
    --run` has none)."""
    info: dict[str, Any] = {"kind": "eval", "params": source.declared()[1]}
    if step is not None and round_no is not None:
        info.update(train_step=int(step), eval_round=int(round_no))
    return info


# ---------------------------------------------------------------------------------------------------------
# Rules-declared worlds
# ---------------------------------------------------------------------------------------------------------
class _GreedyAgent:
    """env_policy.EnvPolicy's acting interface over an `Act` (the library's policy has no action mask);
    an `Act` that can also `decide` (obs -> actions and its PolicyOutput, or None) gives its values to the
    traced games."""

    def __init__(self, act: Act) -> None:
        self._act = act
        if hasattr(act, "decide"):
            self.decide = self._decide

    def act(self, obs: Any, masks: np.ndarray | None = None) -> np.ndarray:
        return np.asarray(self._act(obs))

    def _decide(self, obs: Any, masks: np.ndarray | None = None) -> tuple[np.ndarray, PolicyOutput]:
        actions, output = self._act.decide(obs)
        n = len(np.asarray(actions).reshape(-1))
        return np.asarray(actions), output or PolicyOutput(np.full((n, 0), np.nan, np.float32))


@dataclass
class DeclaredTarget:
    source: EnvSource
    spec: Any = field(repr=False)  # the WorldSpec

    @property
    def name(self) -> str:
        return self.source.name

    def run_meta(self) -> dict[str, Any]:
        """The run's meta of the env; the recorder of its traced games adds the spec's sources, facts and
        board to its config (recording.declared_run_config)."""
        return {"scenario": Path(self.source.name).name, "rule_files": list(self.spec.program.files),
                "config": {"env": self.source.to_json()}}

    def outcome(self, info: Mapping[str, Any], terminated: bool, truncated: bool) -> str:
        # the world's own outcome where it declares a win ([end] win, loss: "win", "loss")
        return str(info.get("outcome", "terminated" if terminated else "truncated"))

    def evaluator(self, writer: TraceWriter, new_id: NewId, settings: EvalSettings) -> Evaluator:
        source = evaluation_env(self.source, settings.level) or self.source
        return DeclaredEvaluator(source, writer, new_id, settings)


class DeclaredEvaluator:
    """The traced games one at a time in one traced env (kept for the run: its program is written once);
    the rest in a vector env of untraced copies, as `train --env` evaluates (env_policy.play_env_games)."""

    def __init__(self, source: EnvSource, writer: TraceWriter, new_id: NewId, settings: EvalSettings,
                 agent_rows: bool = True) -> None:
        """`agent_rows` False: the traced games record the world alone, no decisions or reward terms (bench
        eval's baseline)."""
        self.source, self.settings = source, settings
        self.traced = min(settings.traced, settings.games)
        self.team = team_spec(source)  # several agents: a TeamEnv records each agent's decisions
        if not self.traced:
            self.trace_env: Any = None
        elif self.team is not None:
            from tracelab.envs.declared.play import TeamEnv
            self.trace_env = TeamEnv(self.team, trace_writer=writer, trace_episode_ids=new_id,
                                     trace_agent_rows=agent_rows)
        else:
            self.trace_env = EnvSource(source.name, {**source.kwargs, "trace_writer": writer, "trace_episode_ids":
                                                     new_id, "trace_agent_rows": agent_rows}).make()
        rest = settings.games - self.traced
        self.env = make_vector_env(source, min(settings.envs, rest))[0] if rest else None

    def run(self, act: Act, step: int, round_no: int) -> dict[str, float]:
        return self.play(_GreedyAgent(act), step, round_no).metrics()

    def play(self, agent: Any, step: int, round_no: int) -> EnvEvalResult:
        """One evaluation of `agent` (env_policy.EnvPolicy's `act(obs, masks)`: `train --env`'s policy)."""
        seed = eval_seed(self.settings.seed, round_no)
        result = EnvEvalResult()
        if self.trace_env is not None:
            t0 = time.perf_counter()
            self.trace_env.unwrapped.trace_info(eval_info(self.source, step, round_no))
            for k in range(self.traced):
                self._play_one(agent, seed + 1 + k, result)
            result.seconds["traced"] = time.perf_counter() - t0
        rest = self.settings.games - self.traced
        if rest and self.env is not None:
            t0 = time.perf_counter()
            result.extend(play_env_games(self.env, agent, rest, seed))
            result.seconds["untraced"] = time.perf_counter() - t0
        return result

    def _play_one(self, agent: Any, seed: int, result: EnvEvalResult) -> None:
        """One greedy game in the traced env; one that runs EVAL_STEP_CAP steps without an end is counted
        truncated (its record ends 'aborted' at the next game's reset)."""
        env = self.trace_env
        act = one_env_actor(agent, env) if self.team is None else team_env_actor(agent, env)
        obs, info = env.reset(seed=seed)
        ret, steps, terminated, truncated = 0.0, 0, False, False
        while not (terminated or truncated) and steps < EVAL_STEP_CAP:
            obs, reward, terminated, truncated, info = env.step(act(obs, info))
            ret += float(reward)
            steps += 1
        outcome = None
        if declares_outcomes(env):  # the world declares how a game ends; one cut at the cap is truncated
            outcome = str(info["outcome"]) if "outcome" in info and (terminated or truncated) else "truncated"
        result.add(ret, steps, terminated, not terminated, outcome)

    def close(self) -> None:
        if self.trace_env is not None:
            self.trace_env.close()  # the recorder writes what it kept; the run stays open (trace_episode_ids)
        if self.env is not None:
            self.env.close()


# ---------------------------------------------------------------------------------------------------------
def eval_target(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> EvalTarget:
    """What `env_id` (a declared env's id such as tracelab/FrozenLake-v1, or a spec file) is, for
    recording and evaluating a training on it; a UserError names any other env (its games cannot be traced)."""
    source = EnvSource.given(env_id, dict(env_kwargs or {}))
    env = source.make()
    try:
        spec = getattr(env.unwrapped, "world_spec", None)
    finally:
        env.close()
    if spec is None:
        raise UserError(f"{env_id!r}: not a rules-declared env (tracelab/FrozenLake-v1, "
                        f"a spec file): tracelab cannot trace its games")
    return DeclaredTarget(source, spec)
