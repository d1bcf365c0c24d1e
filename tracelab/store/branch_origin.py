"""What a what-if branch reads of its origin run, and what a branch run says of its origin (`tracelab
whatif`, tracelab/envs/declared/branch.py plays the branch).

Everything here reads the origin through its sandboxed connection (reader.open_run): the world it was
recorded on (the spec's and rule files' texts of its `sources` table, the env's name and keyword
arguments of its config), each episode's seed and recorded steps. A branch run names its origin in its
config under ORIGIN_KEY: the origin run's path and id, the episode, the step, the action taken there.
Bounded: the texts by the store's caps (kind.MAX_SPEC_TEXT, the rule file cap), the steps replayed by
MAX_REPLAY_STEPS ($TRACELAB_WHATIF_MAX_STEPS)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tracelab.errors import UserError
from tracelab.store.kind import run_config, spec_text
from tracelab.store.reader import RunConnection
from tracelab.store.schema import BOARD_BEFORE_DECLARED

if TYPE_CHECKING:  # loaded by recorded_steps only: finding a run's origin (runs, diff) needs no numpy
    import numpy as np

# deferred: the engine's parser (numpy) and numpy load where a branch's origin is read: runs and diff import this
# module and need neither

ORIGIN_KEY = "whatif"
MAX_REPLAY_ENV = "TRACELAB_WHATIF_MAX_STEPS"
MAX_REPLAY_STEPS = 1_000_000  # steps replayed to rebuild a world (the episodes before it on its seed's stream)


def max_replay_steps() -> int:
    """MAX_REPLAY_STEPS, or $TRACELAB_WHATIF_MAX_STEPS (a positive integer)."""
    text = os.environ.get(MAX_REPLAY_ENV)
    if text is None:
        return MAX_REPLAY_STEPS
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise UserError(f"${MAX_REPLAY_ENV}: expected a positive integer, got {text!r}")
    return value


@dataclass(frozen=True)
class RecordedWorld:
    """The world a run was recorded on: the env's name (a registered id or the spec's path as the run
    names it) and keyword arguments, whether the name is a registered id, the spec's path and text, and
    each rule file's path and text."""
    env: str
    env_args: dict[str, Any]
    env_id: str | None
    spec_path: str
    spec_text: str
    rules: tuple[tuple[str, str], ...]


@dataclass
class RecordedSteps:
    """One episode's step rows of one agent, in step order (obs: one row of numbers per step)."""
    step: "np.ndarray"
    action: "np.ndarray"
    reward: "np.ndarray"
    terminated: "np.ndarray"
    truncated: "np.ndarray"
    obs: list[Any] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.step)


def recorded_world(con: RunConnection, run: str) -> RecordedWorld:
    """The spec world of the run (UserError, one line, for a run of no spec world: a RuleSim run, a
    reasoning run, or one whose texts are missing or past the store's caps)."""
    from tracelab.engine.parser import RULE_FILE_CAP
    config = run_config(con)
    text = spec_text(con, config)
    if text is None:
        board = con.execute("SELECT board FROM raw.run").fetchall()
        older = bool(board) and board[0][0] == BOARD_BEFORE_DECLARED  # the war game's, by RuleSim
        what = "a RuleSim run" if older else "not a run of a spec world"
        raise UserError(f"{run}: {what}: whatif rebuilds the world from the spec its run keeps, and this run "
                        "keeps none (record the game with play --env, e.g. rules/gridworld/war.toml)")
    env = config.get("env")
    name, args = (env, config.get("env_args")) if isinstance(env, str) else \
        (env.get("name"), env.get("kwargs")) if isinstance(env, dict) else (None, None)
    spec_rows = con.execute("SELECT path FROM raw.sources WHERE role = 'spec' LIMIT 1").fetchall()
    spec_path = spec_rows[0][0] if spec_rows else config.get("spec_path")
    if not isinstance(name, str) or not isinstance(spec_path, str) or not isinstance(args or {}, dict):
        raise UserError(f"{run}: its config does not name the env it was recorded on (env, spec_path)")
    rows = con.execute("SELECT path, text, bytes FROM raw.sources WHERE role = 'rules' ORDER BY path").fetchall()
    rules = []
    for path, body, size in rows:
        if not isinstance(path, str) or not isinstance(body, str) or size > RULE_FILE_CAP:
            raise UserError(f"{run}: its rule file {path!r} is not kept as text within {RULE_FILE_CAP} bytes")
        rules.append((path, body))
    env_id = config.get("env_id") if isinstance(config.get("env_id"), str) else None
    return RecordedWorld(name, dict(args or {}), env_id, spec_path, text, tuple(rules))


def episode_seeds(con: RunConnection) -> dict[int, int | None]:
    """Every episode's seed (None: not recorded), by episode."""
    return {int(e): (None if s is None else int(s)) for e, s in
            con.execute("SELECT episode, seed FROM raw.episode_begin ORDER BY episode").fetchall()}


def stream_of(seeds: dict[int, int | None], episode: int) -> list[int]:
    """The episodes whose games drew from the seeded stream `episode` drew from, up to it: a game reset
    with its seed (a training's evaluation game, the first game of `play`) starts a stream; the next games
    recorded with the same seed (play's later games, which record their run's seed) continue it."""
    seed = seeds[episode]
    same = [e for e in sorted(seeds) if e <= episode and seeds[e] == seed]
    start = len(same) - 1
    while start > 0 and same[start - 1] == same[start] - 1:
        start -= 1
    return same[start:]


def recorded_steps(con: RunConnection, episode: int, agent: str) -> RecordedSteps:
    """The step rows of `agent` in `episode`."""
    import numpy as np
    rows = con.execute("SELECT step, action, reward, terminated, truncated, obs FROM raw.steps "
                       "WHERE episode = ? AND agent = ? ORDER BY step", [episode, agent]).fetchall()
    cols = list(zip(*rows)) if rows else [[]] * 6
    return RecordedSteps(np.array(cols[0], np.int64), np.array(cols[1], np.int64), np.array(cols[2], np.float64),
                         np.array(cols[3], bool), np.array(cols[4], bool), list(cols[5]))


def step_counts(con: RunConnection, episodes: list[int]) -> dict[int, int]:
    """How many steps each of `episodes` recorded (0 for one with none)."""
    rows = con.execute("SELECT episode, max(step) FROM raw.steps WHERE episode IN (SELECT unnest(?::BIGINT[])) "
                       "GROUP BY episode", [episodes]).fetchall()
    found = {int(e): int(n or 0) for e, n in rows}
    return {e: found.get(e, 0) for e in episodes}


def run_agents(con: RunConnection) -> list[str]:
    return [str(a) for (a,) in con.execute("SELECT DISTINCT agent FROM raw.steps ORDER BY agent LIMIT 17").fetchall()]


def episode_list(con: RunConnection) -> list[int]:
    return [int(e) for (e,) in con.execute(
        "SELECT episode FROM raw.episode_begin UNION SELECT DISTINCT episode FROM raw.steps ORDER BY 1").fetchall()]


# ---- a branch run's own record of its origin ----

@dataclass(frozen=True)
class Origin:
    """Where a branch run branched off: its origin run (path and id), episode, step and action."""
    run: str
    run_id: str
    episode: int
    at: int
    action: str
    recorded_action: str
    policy: str | None

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)

    def describe(self) -> str:
        return (f"branch of {self.run_id}:{self.episode} at step {self.at} ({self.action} instead of "
                f"{self.recorded_action})")


def branch_origin(config: dict[str, Any]) -> Origin | None:
    """The origin a run's config names (ORIGIN_KEY), None for a run that is no branch or names it wrongly
    (a run's config comes from anywhere: each field is checked)."""
    o = config.get(ORIGIN_KEY)
    if not isinstance(o, dict):
        return None
    kinds = {"run": str, "run_id": str, "episode": int, "at": int, "action": str, "recorded_action": str}
    if not all(isinstance(o.get(k), t) and not isinstance(o.get(k), bool) for k, t in kinds.items()):
        return None
    policy = o.get("policy")
    return Origin(o["run"], o["run_id"], o["episode"], o["at"], o["action"], o["recorded_action"],
                  policy if isinstance(policy, str) else None)


def run_origin(con: RunConnection) -> Origin | None:
    """The origin of the run open on `con`, if it is a branch."""
    return branch_origin(run_config(con))


def origin_episode(branch: RunConnection, run: Path) -> int | None:
    """The episode of the run at `run` that the run open on `branch` branched off, None when that run is
    not its origin (its origin is named by path, or by run id when the origin has moved since)."""
    origin = run_origin(branch)
    if origin is None:
        return None
    here = run.resolve()
    return origin.episode if Path(origin.run) == here or origin.run_id == here.name else None
