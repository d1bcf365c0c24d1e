"""The envs' tracer hands the simulator's trace rows over in chunks (tracelab/envs/tracer.py): at an
episode's end, every HANDOVER_STEPS steps, before an env reset and at close. The rows a sink gets are the
same as when they were taken after every step; an episode's rows are all out before its end."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tracelab.envs import tracer
from tracelab.envs.sinks import MemorySink
from tracelab.envs.vector_env import GridWarVectorEnv
from tracelab.game.scenario import builtin_scenario


class LoggingSink(MemorySink):
    """A MemorySink that also logs the order of the calls: ('changes', episodes) / ('end', episode)."""

    def __init__(self) -> None:
        super().__init__()
        self.log: list[tuple[str, Any]] = []

    def changes(self, rows: dict[str, np.ndarray], episode_of_world: np.ndarray, t0_of_world: np.ndarray) -> None:
        super().changes(rows, episode_of_world, t0_of_world)
        self.log.append(("changes", set(rows["episode"].tolist())))

    def end_episode(self, world: int, episode: int, steps: int, outcome: str, rewards: Any) -> None:
        super().end_episode(world, episode, steps, outcome, rewards)
        self.log.append(("end", episode))


def play_vector(sink: MemorySink, steps: int, worlds: int = 3, max_steps: int = 90) -> None:
    env = GridWarVectorEnv(worlds, replace(builtin_scenario("advanced"), max_steps=max_steps), backend="rules",
                           trace_sink=sink)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for k in range(steps):
        env.step(rng.integers(0, 9, env.action_space.shape))
        if k == steps // 2:
            env.reset()  # cuts the running episodes short
    env.close()


def test_chunked_handover_gives_the_rows_of_a_handover_after_every_step(monkeypatch: pytest.MonkeyPatch) -> None:
    chunked = LoggingSink()
    play_vector(chunked, 160)
    monkeypatch.setattr(tracer, "HANDOVER_STEPS", 1)
    every = LoggingSink()
    play_vector(every, 160)
    assert len(chunked.change_chunks) < len(every.change_chunks) / 2  # fewer, bigger handovers
    assert [e["episode"] for e in chunked.ended] == [e["episode"] for e in every.ended]
    for ep in sorted({e["episode"] for e in every.ended}):
        a, b = chunked.rows(ep), every.rows(ep)
        assert a.keys() == b.keys() and len(b["t"]) > 0
        for col in b:
            np.testing.assert_array_equal(a[col], b[col], err_msg=f"episode {ep}, column {col}")


def test_an_episodes_rows_are_out_before_its_end() -> None:
    sink = LoggingSink()
    play_vector(sink, 160)
    aborted = {e["episode"] for e in sink.ended if e["outcome"] == "aborted"}
    assert len(aborted) >= 3 and len(sink.ended) > len(aborted)  # resets cut some short, others finished
    for e in sink.ended:
        end_at = sink.log.index(("end", e["episode"]))
        after = [k for k, (kind, eps) in enumerate(sink.log) if kind == "changes" and e["episode"] in eps]
        assert after and max(after) < end_at, e


def test_rows_wait_at_most_handover_steps_within_an_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tracer, "HANDOVER_STEPS", 6)
    sink = MemorySink()
    env = GridWarVectorEnv(1, replace(builtin_scenario("advanced"), max_steps=500), backend="rules", trace_sink=sink)
    env.reset(seed=0)
    nothing = np.array([8])  # the learner stays put; the episode runs on unless blue ends it
    for k in range(1, 13):
        _, _, term, trunc, _ = env.step(nothing)
        assert not (term[0] or trunc[0]), "this test needs an episode of 12 steps at least (another seed)"
        t = set(sink.rows(0)["t"].tolist()) if sink.change_chunks else set()
        handed_up_to = 6 * (k // 6)  # the last handover's step (none before step 6)
        assert t == (set(range(handed_up_to + 1)) if handed_up_to else set()), k
    env.close()


def test_the_store_gets_every_step_record_in_chunks(tmp_path) -> None:  # noqa: ANN001
    """StoreSink writes step records in chunks (WRITE_ROWS step rows, WRITE_INTERVAL_S, close): the steps
    table holds, per world-step, one row per agent with its team's observation, action and reward, as the
    env handed them over (MemorySink keeps the same calls)."""
    from tracelab.store.reader import open_run
    from tracelab.store.sink import StoreSink
    from tracelab.store.writer import TraceWriter

    memory = MemorySink()
    play_vector(memory, 150)
    writer = TraceWriter(tmp_path / "run", {"command": "pytest", "scenario": "advanced"})
    play_vector(StoreSink(writer), 150)  # the env closes the sink and the writer
    got = open_run(tmp_path / "run").execute(
        "SELECT episode, step, t, agent, action, reward, obs FROM steps ORDER BY episode, step, agent").fetchall()
    want = []
    agents = ["blue-agent-1", "red-agent-1"]  # sorted, as the query orders them
    for chunk in memory.step_chunks:
        for i in range(len(chunk["world"])):
            for team, name in ((1, agents[0]), (0, agents[1])):
                want.append((int(chunk["episode"][i]), int(chunk["t"][i]), int(chunk["t"][i]), name,
                             int(chunk["actions"][i, team, 0]), float(chunk["rewards"][i, team, 0]),
                             chunk["obs"][i, team].tolist()))
    want.sort(key=lambda r: (r[0], r[1], r[3]))
    assert len(got) == len(want) > 300
    for g, w in zip(got, want):
        assert g[:6] == w[:6] and np.allclose(g[6], w[6]), (g[:6], w[:6])
    # ends are written in chunks, but each keeps the time its episode ended: before the next one began
    times = open_run(tmp_path / "run").execute(
        "SELECT world, started_at, ended_at FROM episodes ORDER BY world, episode").fetchall()
    assert len(times) > 6
    for (w0, s0, e0), (w1, s1, _) in zip(times, times[1:]):
        assert s0 <= e0
        if w0 == w1:
            assert e0 <= s1, (w0, s0, e0, s1)
