"""A traced declared env hands the engine's trace rows over in chunks (tracelab/envs/declared/recording.py):
at an episode's end, every HANDOVER_STEPS steps, before a reset and at close. The run it writes is the
one a handover after every step writes; an episode's rows are all written before its end; rows wait at
most HANDOVER_STEPS steps within an episode; the steps table holds every step as the env returned it.
GridWar's advanced game through its spec, written into real runs of the trace store."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tracelab import RULES_DIR
from tracelab.envs.declared import recording
from tracelab.envs.declared.gym_env import DeclaredEnv
from tracelab.store.reader import open_run
from tracelab.store.writer import TraceWriter

WAR = RULES_DIR / "gridworld" / "war.toml"


class LoggingWriter(TraceWriter):
    """A TraceWriter that also logs the order of the calls: ('changes', {episode: its rows' t}) and
    ('end', (episode, its last step's t))."""

    def __init__(self, run_dir: Path) -> None:
        super().__init__(run_dir, {"command": "pytest"})
        self.log: list[tuple[str, Any]] = []

    def write_engine(self, episode: Any, engine: Any, rows: Any = None) -> int:
        ts = {int(e): set(rows["t"][rows["episode"] == e].tolist()) for e in np.unique(rows["episode"])}
        self.log.append(("changes", ts))
        return super().write_engine(episode, engine, rows)

    def end_episodes(self, episodes: Any) -> None:
        self.log += [("end", (int(e["episode"]), int(e["t_end"]))) for e in episodes]
        super().end_episodes(episodes)


def play(writer: TraceWriter, steps: int, max_steps: int = 90) -> list[tuple[int, float, list[float]]]:
    """Random actions in the advanced game, a reset half-way (it cuts the running episode short); returns
    each step's (action, reward, observation) as the env gave them."""
    env = DeclaredEnv(WAR, advanced=True, max_steps=max_steps, trace_writer=writer)
    env.reset(seed=3)
    rng, out = np.random.default_rng(3), []
    for k in range(steps):
        a = int(rng.integers(0, 9))
        obs, reward, terminated, truncated, _ = env.step(a)
        out.append((a, float(reward), obs.tolist()))
        if terminated or truncated or k == steps // 2:
            env.reset()
    env.close()
    return out


def changes(run: Path) -> list[tuple]:
    con = open_run(run)
    try:
        return con.execute("SELECT * EXCLUDE (seq) FROM raw.changes ORDER BY seq").fetchall()
    finally:
        con.close()


def test_chunked_handover_writes_the_run_a_handover_after_every_step_writes(tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    takes = []
    take = recording.DeclaredRecorder._take_rows
    monkeypatch.setattr(recording.DeclaredRecorder, "_take_rows", lambda self: (takes.append(1), take(self)))
    play(TraceWriter(tmp_path / "chunked", {"command": "pytest"}), 160)
    chunked_takes, takes[:] = len(takes), []
    monkeypatch.setattr(recording, "HANDOVER_STEPS", 1)
    play(TraceWriter(tmp_path / "every", {"command": "pytest"}), 160)
    assert chunked_takes < len(takes) / 2  # fewer, bigger handovers
    a, b = changes(tmp_path / "chunked"), changes(tmp_path / "every")
    assert len(a) > 1000 and a == b


def test_an_episodes_rows_are_written_before_its_end(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(recording, "WRITE_ROWS", 1)  # a write after every step: the order shows
    writer = LoggingWriter(tmp_path / "run")
    play(writer, 160)
    ends = [e for kind, e in writer.log if kind == "end"]
    assert len(ends) >= 3
    for e, t_end in ends:
        end_at = writer.log.index(("end", (e, t_end)))
        written = [k for k, (kind, ts) in enumerate(writer.log) if kind == "changes" and e in ts]
        assert written and max(written) < end_at, e
        # up to its last step, under its own id (not taken later, under the next episode's clock)
        assert set().union(*(writer.log[k][1][e] for k in written)) == set(range(t_end + 1)), e


def test_rows_wait_at_most_handover_steps_within_an_episode(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(recording, "HANDOVER_STEPS", 6)
    monkeypatch.setattr(recording, "WRITE_ROWS", 1)
    writer = LoggingWriter(tmp_path / "run")
    env = DeclaredEnv(WAR, advanced=True, max_steps=500, trace_writer=writer)
    env.reset(seed=0)
    nothing = env.world_spec.action_names.index("nothing")  # red stays put: the game runs on unless blue ends it
    for k in range(1, 13):
        _, _, terminated, truncated, _ = env.step(nothing)
        assert not (terminated or truncated), "this test needs an episode of 12 steps at least (another seed)"
        written = set().union(*(ts.get(0, set()) for kind, ts in writer.log if kind == "changes"))
        handed_up_to = 6 * (k // 6)  # the last handover's step (before step 6: the build's rows at t = 0)
        assert written == set(range(handed_up_to + 1)), k
    env.close()


def test_the_store_gets_every_step_as_the_env_returned_it(tmp_path: Path) -> None:
    played = play(TraceWriter(tmp_path / "run", {"command": "pytest"}), 150)
    con = open_run(tmp_path / "run")
    got = con.execute("SELECT action, reward, obs FROM steps ORDER BY episode, step").fetchall()
    con.close()
    assert len(got) == len(played) == 150
    for (a, r, o), (want_a, want_r, want_o) in zip(got, played):
        assert (a, r) == (want_a, want_r) and np.allclose(o, want_o)
