"""A recorder's writes are paced by their cost (tracelab/store/write_pacing.py): a write that cost d seconds
of CPU (in the caller and the writer's publication) waits until the stepping thread has spent K x d of CPU
since, and WRITE_INTERVAL_S of wall time at least; WRITE_MAX_INTERVAL_S after the last write it is due
whatever the CPU. Driven by fake clocks passed in, never by sleeping; then a real recorder's writes follow
its pacing, and the writer reports each publication's CPU."""
from __future__ import annotations

from pathlib import Path

import pytest

from tracelab import RULES_DIR
from tracelab.envs.declared.gym_env import DeclaredEnv
from tracelab.store import write_pacing
from tracelab.store.reader import open_run
from tracelab.store.write_pacing import WRITE_INTERVAL_S, WRITE_MAX_INTERVAL_S, WritePacing
from tracelab.store.writer import TraceWriter

WAR = RULES_DIR / "gridworld" / "war.toml"
K = 10.0


class Clocks:
    """A wall clock and a thread CPU clock that move only when told."""

    def __init__(self) -> None:
        self.wall_s = 100.0
        self.cpu_s = 5.0
        self.publish_s = 0.0
        self.wall_reads = self.cpu_reads = 0

    def wall(self) -> float:
        self.wall_reads += 1
        return self.wall_s

    def cpu(self) -> float:
        self.cpu_reads += 1
        return self.cpu_s

    def pacing(self) -> WritePacing:
        return WritePacing(lambda: self.publish_s, wall=self.wall, cpu=self.cpu, interval_s=0.25, cost_factor=K,
                           max_interval_s=2.0)

    def work(self, wall_s: float, cpu_s: float) -> None:
        self.wall_s += wall_s
        self.cpu_s += cpu_s


def write_costing(clocks: Clocks, pacing: WritePacing, cpu_s: float) -> None:
    pacing.write(lambda: clocks.work(cpu_s, cpu_s))


def test_a_write_that_cost_d_delays_the_next_by_k_times_d_of_the_threads_cpu() -> None:
    c = Clocks()
    pacing = c.pacing()
    write_costing(c, pacing, 0.004)  # 4 ms in the caller
    c.publish_s = 0.016             # and 16 ms in the writer's thread: the next waits for 0.2 s of CPU
    c.work(0.25, 0.1)               # the wall interval has passed, half the CPU
    assert not pacing.due()
    c.work(0.0999, 0.0999)
    assert not pacing.due()         # 0.1999 s of CPU < K x 0.02
    c.work(0.001, 0.0002)
    assert pacing.due()


def test_a_cheap_write_keeps_the_wall_interval() -> None:
    c = Clocks()
    pacing = c.pacing()
    write_costing(c, pacing, 0.001)
    c.publish_s = 0.002  # K x 3 ms = 30 ms of CPU, long spent before the wall interval ends
    c.work(0.249, 0.249)
    assert not pacing.due()
    c.work(0.001, 0.001)
    assert pacing.due()


def test_a_loaded_thread_writes_later_in_wall_time() -> None:
    """The thread gets a tenth of a core: 0.2 s of CPU take 2 s of wall, up to the ceiling."""
    c = Clocks()
    pacing = c.pacing()
    write_costing(c, pacing, 0.002)
    c.publish_s = 0.013  # K x 15 ms = 0.15 s of CPU: 1.5 s of wall at a tenth of a core
    waited = 0.0
    while not pacing.due():
        c.work(0.01, 0.001)
        waited += 0.01
    assert 1.49 < waited < 1.51


def test_the_ceiling_writes_whatever_the_cpu() -> None:
    c = Clocks()
    pacing = c.pacing()
    write_costing(c, pacing, 0.05)
    c.publish_s = 0.5  # K x 0.55 s of CPU: more than the ceiling's 2 s at any share of a core
    c.work(1.99, 0.5)
    assert not pacing.due()
    c.work(0.005, 0.0)
    assert not pacing.due()
    c.work(0.01, 0.0)
    assert pacing.due()


def test_asked_every_step_it_reads_the_cpu_clock_rarely() -> None:
    """Before the wall interval only the wall clock is read; after it, the CPU clock once per deadline
    the CPU owed sets (the thread's CPU runs no faster than the wall clock)."""
    c = Clocks()
    pacing = c.pacing()
    write_costing(c, pacing, 0.01)
    c.publish_s = 0.01  # owes 0.2 s of CPU
    reads = c.cpu_reads
    steps = 0
    while not pacing.due():
        c.work(0.0001, 0.00005)  # a step of 0.1 ms of wall, at half a core
        steps += 1
    assert 3999 <= steps <= 4001  # 0.4 s of wall for 0.2 s of CPU
    assert c.cpu_reads - reads <= 20


def test_a_recorder_writes_when_its_pacing_says(tmp_path: Path) -> None:
    """A real traced env's recorder: nothing reaches the writer until its pacing says a write is due; then
    every step kept so far does (read back from the run)."""
    writer = TraceWriter(tmp_path / "run", {"command": "pytest"})
    env = DeclaredEnv(WAR, max_steps=500, trace_writer=writer)
    c = Clocks()
    env.unwrapped._recorder.pacing = c.pacing()
    env.reset(seed=0)
    nothing = env.unwrapped.world_spec.action_names.index("nothing")

    def step() -> None:
        c.work(0.125, 0.125)  # seconds of wall and CPU a step (binary fractions: the sums are exact)
        _, _, terminated, truncated, _ = env.step(nothing)
        assert not (terminated or truncated), "this test needs an episode of 7 steps at least (another seed)"

    def stored_steps() -> int:
        writer.flush()
        con = open_run(tmp_path / "run")
        try:
            return con.execute("SELECT count(*) FROM steps").fetchone()[0]
        finally:
            con.close()

    step()
    assert stored_steps() == 0  # the first write is due after 0.25 s of wall
    step()
    assert stored_steps() == 2
    c.publish_s = 0.0625  # the next write owes K x 0.0625 = 0.625 s of the thread's CPU: 5 steps
    for _ in range(4):
        step()
    assert stored_steps() == 2
    step()
    assert stored_steps() == 7
    env.close()


def test_the_writer_reports_its_last_publications_cpu(tmp_path: Path) -> None:
    with TraceWriter(tmp_path / "run", {"command": "pytest"}) as writer:
        assert writer.last_publish_cpu_s == 0.0
        writer.write_metrics(0, {"loss": 1.0})
        writer.flush()
        assert writer.last_publish_cpu_s > 0.0


def test_the_defaults_keep_a_quarter_second_and_a_ceiling() -> None:
    assert WRITE_INTERVAL_S == 0.25 and WRITE_INTERVAL_S < WRITE_MAX_INTERVAL_S <= 2.0


def test_a_program_sets_the_constants_before_it_makes_its_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(write_pacing, "WRITE_COST_FACTOR", 2.0)
    c = Clocks()
    pacing = WritePacing(lambda: c.publish_s, wall=c.wall, cpu=c.cpu)
    write_costing(c, pacing, 0.1)  # owes 2 x 0.1 s of CPU (the default factor: 1 s)
    c.work(0.25, 0.25)
    assert pacing.due()
