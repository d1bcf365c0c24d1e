"""`tracelab bench play`: how fast `tracelab play` records games into the trace store, against the
simulator's own traced loop, and how much memory a long recorded run holds.

Speed, in one process, for one world and `worlds` worlds (default 64): the scenario of
`tracelab play --scenario base` (red: the scripted base policy, blue: the scripted opponent, seed 1).
- `loop`: bench env's traced stepping loop (tracelab.bench.sims.Loop, red scripted): the simulator steps,
  finished worlds reset, the trace taken as the envs' tracer takes it; nothing is kept;
- `play`: what `tracelab play --run` does after its first step (tracelab.playing.Games into a StoreSink
  and a TraceWriter on a new run, closed at the end: the last rows written), `episodes` episodes;
- `play_untraced`: the same without a run (`--no-trace`).
Each figure is steps/s (batched steps; x worlds for env-steps), the median of `repeats` blocks of about
a second taken in turn (loop, play, untraced play, ...), so the three see the same load. `ratio`: play's
median over the loop's (the goal: >= 0.7 at both sizes). `steps_per_cpu_s`, `cpu_ratio`: the same per CPU
second of the process (all threads, the store writer's too), which leaves out a busy machine's waits
for a core.

Memory (`--memory`, or `memory_episodes`): `tracelab play --scenario advanced --seed 3 --run R
--episodes N` for N = 100, 1,000 and 10,000 (`--quick`: 100, 1,000), each in a fresh process
(`python -m tracelab.bench.play EPISODES`), the resident memory sampled every tenth of the episodes and
the peak (VmHWM). The goal: the peak <= 300 MB at any length, flat after warm-up."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tracelab.bench.common import calibrate, format_table, high_water_bytes, machine_info, rss_bytes, summarize
from tracelab.bench.engine import machine_line
from tracelab.bench.sims import Loop
from tracelab.game.rulesim import RuleSim
from tracelab.game.scenario import builtin_scenario
from tracelab.playing import Games
from tracelab.store import TraceWriter
from tracelab.store.sink import StoreSink

GOAL_RATIO = 0.7
GOAL_PEAK_MB = 300
SCENARIO, SEED = "base", 1
MEMORY_SCENARIO, MEMORY_SEED = "advanced", 3


def _play(scenario: Any, episodes: int, worlds: int, run_dir: Path | None) -> tuple[int, float, float]:
    """A `tracelab play` of `episodes` episodes (into a new run at `run_dir`, or untraced): (batched
    steps after the first, wall and CPU seconds from after the first step to the run closed)."""
    sink = None if run_dir is None else StoreSink(TraceWriter.open(run_dir, {"command": "tracelab bench play",
                                                                            "scenario": scenario.name}))
    games = Games(scenario, episodes, worlds=worlds, seed=SEED, sink=sink)
    games.step()  # the first step is not timed by play either (it holds any compiling)
    steps = 0
    t0, c0 = time.perf_counter(), time.process_time()
    while not games.done:
        games.step()
        steps += 1
    games.close()
    return steps, time.perf_counter() - t0, time.process_time() - c0


def speed(worlds: int, repeats: int, target_s: float, tmp: Path) -> dict[str, Any]:
    """The loop, play traced and play untraced at `worlds` worlds, in turn (module docstring)."""
    scenario = builtin_scenario(SCENARIO)
    loop = Loop(RuleSim(scenario, worlds, seed=SEED, trace=True), True, seed=SEED, red="scripted")
    loop.run(100)  # the first steps ground the rules that the start left ungrounded: not a block's pace
    block = calibrate(loop.run, target_s)
    loop.run(block)  # warm-up at full size
    # episodes for a block of play: from a warm-up play, its steps per episode
    probe = max(worlds * 10, 20)
    steps, _, _ = _play(scenario, probe, worlds, tmp / f"probe-{worlds}")
    episodes = max(worlds, int(probe * block / max(steps, 1)))
    names = ("loop", "play", "play_untraced")
    wall: dict[str, list[float]] = {name: [] for name in names}
    cpu: dict[str, list[float]] = {name: [] for name in names}
    for i in range(max(1, repeats)):
        t0, c0 = time.perf_counter(), time.process_time()
        loop.run(block)
        wall["loop"].append(block / (time.perf_counter() - t0))
        cpu["loop"].append(block / (time.process_time() - c0))
        for name, run_dir in (("play", tmp / f"run-{worlds}-{i}"), ("play_untraced", None)):
            steps, seconds, cpu_s = _play(scenario, episodes, worlds, run_dir)
            wall[name].append(steps / seconds)
            cpu[name].append(steps / cpu_s)
        shutil.rmtree(tmp / f"run-{worlds}-{i}", ignore_errors=True)
    out: dict[str, Any] = {"worlds": worlds, "loop_steps": block, "play_episodes": episodes}
    for name in names:
        out[name] = {"steps_per_s": summarize(wall[name]).to_dict(),
                     "env_steps_per_s": summarize([v * worlds for v in wall[name]]).to_dict(),
                     "steps_per_cpu_s": summarize(cpu[name]).to_dict()}
    med = lambda name, key="steps_per_s": out[name][key]["median"]  # noqa: E731
    out["ratio"] = med("play") / med("loop")
    out["untraced_ratio"] = med("play_untraced") / med("loop")
    out["cpu_ratio"] = med("play", "steps_per_cpu_s") / med("loop", "steps_per_cpu_s")
    out["untraced_cpu_ratio"] = med("play_untraced", "steps_per_cpu_s") / med("loop", "steps_per_cpu_s")
    out["goal_met"] = out["ratio"] >= GOAL_RATIO
    return out


def memory(episodes: int) -> dict[str, Any]:
    """`tracelab play --scenario advanced --seed 3 --run R --episodes N` in a fresh process: its RSS at
    every tenth of the episodes and its peak."""
    proc = subprocess.run([sys.executable, "-m", "tracelab.bench.play", str(episodes)], capture_output=True,
                          text=True, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"the memory child failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run(quick: bool = False, repeats: int = 5, worlds: int = 64, memory_lengths: list[int] | None = None
        ) -> dict[str, Any]:
    info = machine_info()
    target_s = 0.2 if quick else 1.0
    sizes = sorted({1, 8 if quick else worlds})
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-play-") as tmp:
        rows = [speed(w, repeats, target_s, Path(tmp)) for w in sizes]
    mem = [memory(n) for n in (memory_lengths or [])]
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "scenario": SCENARIO, "speed": rows,
            "memory": mem}


def report(r: dict[str, Any]) -> str:
    med = lambda d: d["steps_per_s"]["median"]  # noqa: E731
    sp = lambda d: f"{100 * d['steps_per_s']['spread']:.0f}%"  # noqa: E731
    cpu = lambda d: d["steps_per_cpu_s"]["median"]  # noqa: E731
    parts = [machine_line(r["machine"], r["quick"], r["repeats"]),
             f"play --scenario {r['scenario']} (red scripted) against bench env's traced loop, steps/s (batched)\n"
             + format_table(["worlds", "loop", "play traced", "play untraced", "traced/loop", "untraced/loop",
                             "spread loop/play/untraced", f"goal >= {GOAL_RATIO}"],
                            [[s["worlds"], med(s["loop"]), med(s["play"]), med(s["play_untraced"]), s["ratio"],
                              s["untraced_ratio"], "/".join(sp(s[k]) for k in ("loop", "play", "play_untraced")),
                              "met" if s["goal_met"] else "not met"] for s in r["speed"]]),
             "the same in steps per CPU second of the process (all threads: the writer's too; steadier on a "
             "busy machine)\n" + format_table(
                 ["worlds", "loop", "play traced", "play untraced", "traced/loop", "untraced/loop"],
                 [[s["worlds"], cpu(s["loop"]), cpu(s["play"]), cpu(s["play_untraced"]), s["cpu_ratio"],
                   s["untraced_cpu_ratio"]] for s in r["speed"]])]
    if r["memory"]:
        parts.append(f"play --scenario {MEMORY_SCENARIO} --seed {MEMORY_SEED} --run R, a fresh process each "
                     "(RSS MB at each tenth of the episodes)\n" + format_table(
                         ["episodes", "peak MB", "after 10%", "last", "rise after 10%", "samples",
                          f"goal <= {GOAL_PEAK_MB} MB"],
                         [[m["episodes"], m["peak_mb"], m["rss_mb"][0], m["rss_mb"][-1],
                           max(m["rss_mb"]) - m["rss_mb"][0],  # flat after warm-up: a few MB
                           " ".join(f"{x:.0f}" for x in m["rss_mb"]),
                           "met" if m["peak_mb"] <= GOAL_PEAK_MB else "not met"] for m in r["memory"]]))
    return "\n\n".join(parts)


def _memory_child(episodes: int) -> dict[str, Any]:
    """Play `episodes` episodes as `tracelab play --scenario advanced --seed 3 --run R` does (one world),
    sampling RSS every tenth of them."""
    scenario = builtin_scenario(MEMORY_SCENARIO)
    tmp = Path(tempfile.mkdtemp(prefix="tracelab-bench-play-memory-"))
    try:
        sink = StoreSink(TraceWriter.open(tmp / "run", {"command": "tracelab bench play", "scenario": scenario.name}))
        games = Games(scenario, episodes, seed=MEMORY_SEED, sink=sink)
        samples, next_at = [], max(1, episodes // 10)
        t0 = time.perf_counter()
        while not games.done:
            games.step()
            if len(games.finished) >= next_at:
                samples.append(rss_bytes() / 2**20)
                next_at += max(1, episodes // 10)
        games.close()
        seconds = time.perf_counter() - t0
        run_mb = sum(f.stat().st_size for f in (tmp / "run").rglob("*") if f.is_file()) / 2**20
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"episodes": episodes, "rss_mb": samples, "peak_mb": high_water_bytes() / 2**20,
            "seconds": seconds, "run_mb": run_mb}


if __name__ == "__main__":
    print(json.dumps(_memory_child(int(sys.argv[1]))))
