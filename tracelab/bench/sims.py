"""Simulator workloads shared by `bench engine` and `bench env`: the scenarios by team size, a pool of
built RuleSims (the 20-agent game takes a minute to ground, so `bench all` builds each size once), the
timed stepping loop (fixed-seed random red, scripted blue, finished worlds reset, trace drained), and the
engine alone replaying that loop's steps (what the simulator around it costs)."""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tracelab.bench.common import Summary, calibrate, median_of, rates, summarize
from tracelab.envs.tracer import handover_due
from tracelab.game.refsim import RefSim
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import Scenario, builtin_scenario, generate_scenario

Sim = RuleSim | RefSim
_POOL: dict[tuple[str, int, int, str], tuple[Sim, float]] = {}


def scenario_for(agents: int) -> Scenario:
    """The 8x8 map with `agents` per team: the built-in advanced scenario for 1, else a generated map."""
    if agents == 1:
        return builtin_scenario("advanced")
    return generate_scenario(8, 8, agents, 0.1, seed=1, advanced=True)


def get_sim(kind: str, agents: int, worlds: int, kernel: str = "auto") -> tuple[Sim, float]:
    """A simulator ("rules" or "reference") and the seconds its construction took, built once per size.
    RuleSims are built with trace=True; `set_trace` switches the engine's per-world trace flags, which is
    all that RuleSim(trace=False) sets differently. `kernel`: the RuleSim engine's (Engine(kernel=...))."""
    key = (kind, agents, worlds, kernel)
    if key not in _POOL:
        t0 = time.perf_counter()
        sc = scenario_for(agents)
        sim = RuleSim(sc, worlds, seed=0, trace=True, kernel=kernel) if kind == "rules" else RefSim(sc, worlds, seed=0)
        _POOL[key] = (sim, time.perf_counter() - t0)
    return _POOL[key]


def release(kind: str, agents: int, worlds: int, kernel: str = "auto") -> None:
    """Forget a pooled simulator (the batched 20-agent ones hold gigabytes)."""
    _POOL.pop((kind, agents, worlds, kernel), None)


def set_trace(sim: Sim, on: bool) -> None:
    if isinstance(sim, RuleSim):
        sim.engine.trace_on[:] = on
        sim.take_trace()  # start with an empty buffer


class EngineTimer:
    """Accumulates the seconds spent inside `sim.engine.step()` (an instance attribute shadows the
    method while installed); for a RuleSim stepping in one compiled call (fused), inside that call too,
    which holds the engine's step and also the actions' rows, the read-back and the observations."""

    def __init__(self, sim: RuleSim) -> None:
        self.sim = sim
        self.engine = sim.engine
        self.seconds = 0.0
        self._fused = sim._fused_call  # noqa: SLF001 (RuleSim's hook for this timer)
        self.engine.step = self._timed(type(self.engine).step.__get__(self.engine))  # type: ignore[method-assign]
        sim._fused_call = self._timed(self._fused)  # noqa: SLF001

    def _timed(self, inner: Any) -> Any:
        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - t0
        return timed

    def remove(self) -> None:
        del self.engine.step
        self.sim._fused_call = self._fused  # noqa: SLF001


@dataclass
class Loop:
    """Steps `sim` with a fixed-seed random red policy and the scripted blue policy, resetting finished
    worlds and (with `trace`) taking the trace when the envs' tracer would (tracer.handover_due: when an
    episode ended, else every HANDOVER_STEPS steps), so that a traced figure is what a traced run pays.
    `red="scripted"`: red plays the scripted base policy instead (sim.scripted_actions("red"), timed),
    as `tracelab play` does by default."""
    sim: Sim
    trace: bool
    seed: int = 0
    red: str = "random"
    rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self._steps_waiting = 0
        self.ids = np.asarray(self.sim.scenario.action_ids, np.int64)
        self.shape = (self.sim.n_worlds, self.sim.scenario.agents_per_team)
        set_trace(self.sim, self.trace)
        self.sim.reset(seed=self.seed)

    def run(self, steps: int) -> None:
        sim = self.sim
        scripted = self.red == "scripted"
        red = None if scripted else self.rng.choice(self.ids, (steps, *self.shape))
        drain = self.trace and isinstance(sim, RuleSim)
        for i in range(steps):
            res = sim.step(sim.scripted_actions("red") if scripted else red[i], sim.scripted_actions("blue"))
            done = res.terminated | res.truncated
            ended = bool(done.any())
            if drain and self._handover_due(ended):
                sim.take_trace()
            if ended:
                sim.reset(worlds=done)

    def _handover_due(self, episode_ended: bool) -> bool:
        self._steps_waiting += 1
        if handover_due(self.sim, self._steps_waiting, episode_ended):  # type: ignore[arg-type]
            self._steps_waiting = 0
            return True
        return False


def measure(sim: Sim, trace: bool, repeats: int, target_s: float, engine_time: bool = True,
            red: str = "random") -> dict[str, Any]:
    """Steps/s of `sim` (median over `repeats` blocks of a calibrated number of steps), env-steps/s
    (times the worlds), and for a RuleSim the engine's share: seconds per step inside engine.step() and
    its work counters (engine.stats) per world-step. `red`: Loop's red policy."""
    loop = Loop(sim, trace, red=red)
    block = calibrate(loop.run, target_s)
    loop.run(block)  # warm-up at full size: first touches of big batched arrays, caches, allocator
    rules = isinstance(sim, RuleSim)
    timer = EngineTimer(sim) if rules and engine_time else None
    before = sim.engine.stats if rules else {}
    durations, engine_s = [], []
    try:
        for _ in range(max(1, repeats)):
            if timer:
                timer.seconds = 0.0
            t0 = time.perf_counter()
            loop.run(block)
            durations.append(time.perf_counter() - t0)
            if timer:
                engine_s.append(timer.seconds / block)
    finally:
        if timer:
            timer.remove()
    steps_s = rates(summarize(durations), block)
    out: dict[str, Any] = {
        "worlds": sim.n_worlds, "agents": sim.scenario.agents_per_team, "trace": trace,
        "steps_per_repeat": block, "steps_per_s": steps_s.to_dict(),
        "env_steps_per_s": _scaled(steps_s, sim.n_worlds).to_dict()}
    if rules and timer:
        eng = summarize(engine_s)
        out["engine_s_per_step"] = eng.to_dict()
        out["engine_share"] = eng.median * steps_s.median
    if rules:
        after = sim.engine.stats
        world_steps = block * len(durations) * sim.n_worlds
        out["stats_per_step"] = {k: float((after[k] - before[k]).sum()) / world_steps for k in after}
    return out


def _scaled(s: Summary, factor: float) -> Summary:
    return summarize([v * factor for v in s.runs])


class _Recorder:
    """Records what a RuleSim asks of its engine during a stepping loop: each step's external fact rows
    (copies) and each restore, in order (instance attributes shadow the methods while installed). The
    simulator takes its separate calls meanwhile (fused=False), which ask the engine for the same work."""

    def __init__(self, sim: RuleSim) -> None:
        self.sim, self._fused = sim, sim.fused
        sim.fused = False
        self.engine = sim.engine
        self.calls: list[tuple[str, Any]] = []
        step = type(self.engine).step.__get__(self.engine)
        restore = type(self.engine).restore.__get__(self.engine)

        def record_step(external: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
            self.calls.append(("step", tuple(a.copy() for a in external)))
            step(external=external)

        def record_restore(snap: dict[str, object], worlds: np.ndarray) -> None:
            self.calls.append(("restore", (snap, np.array(worlds))))
            restore(snap, worlds)

        self.engine.step = record_step  # type: ignore[method-assign]
        self.engine.restore = record_restore  # type: ignore[method-assign]

    def remove(self) -> None:
        del self.engine.step
        del self.engine.restore
        self.sim.fused = self._fused


def replay_calls(eng: Any, calls: list[tuple[str, Any]], trace: bool) -> None:
    """Do again what a _Recorder recorded: each step with its fact rows (renumbered, as external ids only
    grow), each restore; the trace taken after every step with `trace`."""
    for kind, args in calls:
        if kind == "step":
            ptr, rows, bounds = args
            rows[:, 2] = eng.next_external_id() + np.arange(len(rows))
            eng.step(external=(ptr, rows, bounds))
            if trace:
                eng.take_trace()
        else:
            eng.restore(*args)


def record_replay(loop: Loop, steps: int) -> tuple[Callable[[], None], int]:
    """Run `steps` steps of `loop` (a RuleSim's) with its engine's calls recorded (_Recorder); returns a
    replay of that work from the engine state before it (restored each time, then replay_calls) and the
    number of engine steps it makes. The replay moves the engine on without the RuleSim knowing."""
    eng = loop.sim.engine
    start = eng.snapshot()
    rec = _Recorder(loop.sim)
    try:
        loop.run(steps)
    finally:
        rec.remove()
    everywhere = np.arange(loop.sim.n_worlds)

    def replay() -> None:
        eng.restore(start, everywhere)
        replay_calls(eng, rec.calls, loop.trace)
    return replay, sum(1 for kind, _ in rec.calls if kind == "step")


def measure_engine_only(sim: RuleSim, trace: bool, repeats: int, target_s: float) -> dict[str, Any]:
    """Steps/s of the engine alone on the stepping loop's own work: a block of the loop (Loop) is
    recorded once, then replayed `repeats` times from the same engine state: the same fact rows each step
    (renumbered, as external ids only grow), the same restores at episode ends, the trace taken after
    every step with `trace` (Engine.take_trace, without RuleSim's episode clock). What the loop costs on
    top of this is the simulator around the engine: actions to rows, read-back, rewards, observations,
    the opponent. `same_work`: the first replay made as many firings and changes as the recorded loop.
    The replay moves the engine on without the RuleSim knowing: use a simulator of its own
    (not a pooled one) and drop it afterwards."""
    loop = Loop(sim, trace)
    block = calibrate(loop.run, target_s)
    eng = sim.engine
    before = eng.stats
    replay, steps = record_replay(loop, block)
    recorded = _work(before, eng.stats)
    before = eng.stats
    replay()  # warm-up, and the check that the replay does the loop's work
    same_work = _work(before, eng.stats) == recorded
    steps_s = rates(median_of(replay, repeats), steps)
    return {"worlds": sim.n_worlds, "agents": sim.scenario.agents_per_team, "trace": trace,
            "steps_per_repeat": steps, "steps_per_s": steps_s.to_dict(),
            "env_steps_per_s": _scaled(steps_s, sim.n_worlds).to_dict(), "same_work": same_work}


def _work(before: dict[str, np.ndarray], after: dict[str, np.ndarray]) -> dict[str, int]:
    """The engine's firings and changes between two readings of Engine.stats, summed over worlds."""
    return {k: int((after[k] - before[k]).sum()) for k in ("firings", "changes")}
