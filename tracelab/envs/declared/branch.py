"""A what-if branch of a recorded game of a spec world (`tracelab whatif`, docs/whatif.md): the world
rebuilt at a step from the run alone, another action taken there, the game played on and recorded.

Rebuilding. The world is the one the run keeps: its spec's and rule files' texts (the `sources` table,
read by store/branch_origin.py) are written into a private temporary folder at their places relative to
the spec (a path that leaves it is refused) and loaded from there; the run's env keyword arguments, and a
registered id's own (its step limit too), are applied as when it was recorded. Its draws come from the
env's seeded generator: a game reset with its seed starts a stream, the next games of the run on the same
seed continue it (play's), so the episodes of the stream before the branched one are replayed, untraced,
with their recorded actions, and the generator's state at the branched game's reset is carried over. The
replay is checked step by step against the record (observation and reward): a world that does not
replay as recorded is refused, never branched.

Branching. In the recorded run (`BranchPlan.play`) the game replays its recorded actions up to the step
before `at`, takes the chosen action at `at`, and plays on with a policy's greedy actions (`--policy`)
or the recorded ones (which stop the branch when they run out), at most `steps` steps after `at`."""
from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.engine.safe_files import FileRefused, path_inside
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.play import make_declared_env
from tracelab.envs.declared.recording import flat_observation
from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.errors import UserError, close_names
from tracelab.store.branch_origin import (
    Origin,
    RecordedSteps,
    RecordedWorld,
    episode_list,
    episode_seeds,
    max_replay_steps,
    recorded_steps,
    recorded_world,
    run_agents,
    step_counts,
    stream_of,
)
from tracelab.store.reader import RunConnection

STEP_CAP = 10_000  # a branch played on by a greedy policy in a world without a step limit ends here


@contextmanager
def rebuilt_spec(world: RecordedWorld) -> Iterator[WorldSpec]:
    """The run's spec loaded from its kept texts, in a temporary folder (removed afterwards; the spec's
    texts are read from it while the spec is in use: a traced env records them)."""
    with tempfile.TemporaryDirectory(prefix="tracelab-whatif-") as folder:
        spec_dir = os.path.dirname(world.spec_path)
        spec_file = Path(folder) / (os.path.basename(world.spec_path) or "spec.toml")
        for path, text in world.rules:
            try:
                target = path_inside(folder, os.path.relpath(path, spec_dir))
            except FileRefused as e:
                raise UserError(f"the run's rule file {path!r} is not in its spec's folder: {e}") from None
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text)
        spec_file.write_text(world.spec_text)
        yield load_spec(spec_file, **world_params(world))


def world_params(world: RecordedWorld) -> dict[str, Any]:
    """The spec's params as when the run was recorded: a registered id's own fixed ones, then the run's."""
    if world.env_id is None:
        return dict(world.env_args)
    return EnvSource(world.env_id, dict(world.env_args)).declared()[1]


def make_env(world: RecordedWorld, spec: WorldSpec, **options: Any) -> Any:
    """The env over the rebuilt `spec`: through the registered id (its step limit) or as a spec file."""
    return make_declared_env(EnvSource(world.env_id or world.spec_path, dict(world.env_args)), spec, **options)


def _generator(state: dict[str, Any]) -> np.random.Generator:
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = state
    return rng


@dataclass
class BranchPlan:
    """What the branch replays and plays: the origin's world, the branched episode's recorded steps,
    the stream replayed before it, the step and action of the branch."""
    run: str
    run_id: str
    world: RecordedWorld
    episode: int
    agent: str
    at: int
    steps_after: int | None
    recorded: RecordedSteps
    stream: list[tuple[int, RecordedSteps]]        # the episodes before it on its seed's stream
    seed: int
    action: int = -1
    action_name: str = ""
    rng_state: dict[str, Any] | None = None   # the generator at the branched game's reset (None: seeded there)

    @property
    def recorded_action(self) -> int:
        return int(self.recorded.action[self.at - 1])

    def origin(self, spec: WorldSpec, run_path: str, policy: str | None) -> Origin:
        """What the branch run records of its origin (`run_path`: the origin run's resolved path)."""
        return Origin(run_path, self.run_id, self.episode, self.at, self.action_name,
                      spec.action_names[self.recorded_action], policy)

    def rehearse(self, spec: WorldSpec, action: str, kernel: str = "auto") -> None:
        """Check the request against the rebuilt world before anything is written: the action's name, the
        replay of the stream and of the episode up to `at` as recorded, the action allowed there by the
        mask. Keeps the generator's state at the episode's reset (rng_state)."""
        names = list(spec.action_names)
        if action not in names:
            near = close_names(action, names)
            raise UserError(f"--action {action!r}: no such action (the spec's: {', '.join(names)})"
                            + (f"; did you mean {', '.join(near)}?" if near else ""))
        self.action, self.action_name = names.index(action), action
        env = make_env(self.world, spec, kernel=kernel)
        try:
            for k, (episode, steps) in enumerate(self.stream):
                env.reset(seed=self.seed if k == 0 else None)
                self._replay(env, episode, steps, len(steps))
            # the generator at the game's reset: carried over from the stream, or seeded there
            self.rng_state = dict(env.unwrapped.np_random.bit_generator.state) if self.stream else None
            _, info = env.reset(seed=None if self.stream else self.seed)
            info = self._replay(env, self.episode, self.recorded, self.at - 1, info)
        finally:
            env.close()
        mask = info.get("action_mask")
        if mask is not None and not mask[self.action]:
            allowed = [n for n, ok in zip(names, np.asarray(mask).tolist()) if ok]
            raise UserError(f"--action {action}: masked at step {self.at} of episode {self.episode} (allowed "
                            f"there: {', '.join(allowed) or 'none'})")

    def _replay(self, env: Any, episode: int, steps: RecordedSteps, n: int,
                info: dict[str, Any] | None = None) -> dict[str, Any]:
        """Step `env` through the first `n` recorded steps, each checked against the record."""
        info = info or {}
        for k in range(n):
            obs, reward, terminated, truncated, info = env.step(int(steps.action[k]))
            self._check(episode, k, steps, obs, reward)
        return info

    def _check(self, episode: int, k: int, steps: RecordedSteps, obs: Any, reward: float) -> None:
        recorded = steps.obs[k] if k < len(steps.obs) else None
        same_obs = recorded is None or np.array_equal(flat_observation(obs), np.asarray(recorded, np.float32))
        if not same_obs or float(reward) != float(steps.reward[k]):
            raise UserError(f"{self.run}: episode {episode} does not replay as recorded (step {k + 1}: "
                            f"{'the observation' if not same_obs else 'the reward'} differs): the run's draws "
                            "came from a generator whatif cannot rebuild; refused")

    def play(self, spec: WorldSpec, writer: Any, policy: Any = None, kernel: str = "auto",
             begin_info: dict[str, Any] | None = None) -> dict[str, Any]:
        """Record the branch into `writer` (closed at the end): the recorded steps before `at`, the chosen
        action at `at`, then `policy`'s greedy actions (an EnvPolicy) or the recorded ones. Returns its
        steps, return, whether it ended, and why it stopped when it did not."""
        env = make_env(self.world, spec, kernel=kernel, trace_writer=writer)
        try:
            env.unwrapped.trace_info(begin_info)
            if self.rng_state is not None:
                env.unwrapped.np_random = _generator(self.rng_state)
            obs, info = env.reset(seed=self.seed if self.rng_state is None else None)
            act = self._actor(env, policy)
            ret, n, ended, stopped = 0.0, 0, False, None
            while not ended:
                if self.steps_after is not None and n - self.at >= self.steps_after:
                    stopped = f"--steps {self.steps_after} played after step {self.at}"
                    break
                if n >= STEP_CAP:
                    stopped = f"{STEP_CAP} steps played without an end"
                    break
                a = act(n + 1, obs, info)
                if a is None:
                    stopped = f"the recorded actions ran out after step {n}"
                    break
                obs, reward, terminated, truncated, info = env.step(a)
                ret += float(reward)
                n += 1
                ended = terminated or truncated
        except BaseException:
            env.unwrapped.close(status="failed")
            raise
        env.close()
        return {"steps": n, "return": ret, "ended": ended, "stopped": stopped}

    def _actor(self, env: Any, policy: Any) -> Callable[[int, Any, dict[str, Any]], int | None]:
        """The action of step k: recorded before `at`, the chosen one at `at`, then the policy's or the
        recorded one (None: there is none)."""
        greedy = None
        if policy is not None:
            # deferred: loads torch, which a branch on the recorded actions does not need
            from tracelab.train.env_policy import greedy_actor
            greedy = greedy_actor(policy, env)

        def act(k: int, obs: Any, info: dict[str, Any]) -> int | None:
            if k == self.at:
                return self.action
            if k < self.at or greedy is None:
                return int(self.recorded.action[k - 1]) if k <= len(self.recorded) else None
            return greedy(obs, info)
        return act


def plan_branch(con: RunConnection, run: str, run_id: str, episode: int, at: int, agent: str | None,
                steps_after: int | None) -> BranchPlan:
    """What to replay for a branch of `episode` at step `at` (UserError, one line, for an episode, step or
    agent the run lacks, a run of several agents, or a replay past max_replay_steps)."""
    world = recorded_world(con, run)
    episodes = episode_list(con)
    if episode not in episodes:
        shown = f"{episodes[0]}..{episodes[-1]}" if episodes else "none"
        raise UserError(f"{run}: no episode {episode} (its episodes: {shown})")
    agents = run_agents(con)
    if len(agents) > 1:
        raise UserError(f"{run}: a game of {len(agents)} agents ({', '.join(agents[:4])}...); whatif branches "
                        "one-agent games for now")
    if agent is not None and agents and agent not in agents:
        raise UserError(f"--agent {agent!r}: the run's agent is {agents[0]!r}")
    name = agent or (agents[0] if agents else "")
    recorded = recorded_steps(con, episode, name)
    if not len(recorded):
        raise UserError(f"{run}: episode {episode} records no steps (only traced games keep theirs: play --env, "
                        "train --env's traced evaluations)")
    if at < 1 or at > len(recorded):
        raise UserError(f"--at {at}: episode {episode} has {len(recorded)} step(s) (--at counts them from 1)")
    seeds = episode_seeds(con)
    seed = seeds.get(episode)
    if seed is None:
        raise UserError(f"{run}: episode {episode} records no seed: its draws cannot be replayed")
    before = stream_of(seeds, episode)[:-1]
    counts = step_counts(con, before)
    total = sum(counts.values()) + at
    if total > max_replay_steps():
        raise UserError(f"rebuilding episode {episode} replays {total:,} steps (the games before it on its seed), "
                        f"over the {max_replay_steps():,} allowed; raise $TRACELAB_WHATIF_MAX_STEPS")
    stream = [(e, recorded_steps(con, e, name)) for e in before]
    return BranchPlan(run, run_id, world, episode, name, at, steps_after, recorded, stream, seed)
