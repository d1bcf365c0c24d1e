"""`tracelab bench play`: how fast `tracelab play` records games into the trace store, against the
spec path's own traced loop, and how much memory a long recorded run holds.

Speed, in one process, one world (what `tracelab play` plays): `tracelab play --scenario base` (the war game's
base game through its spec, rules/gridworld/war.toml; red random, blue: the rules' opponent, seed 1).
- `loop`: bench env's traced stepping loop (tracelab.bench.sims.SpecLoop): the world steps, finished
  episodes restart, the trace taken as the envs' tracer takes it; nothing is kept;
- `play`: what `tracelab play --run` does after its first step (the declared env with a TraceWriter on a new
  run, play_episodes, closed at the end: the last rows written), `episodes` episodes;
- `play_untraced`: the same without a run (`--no-trace`).
Each figure is steps/s, the median of `repeats` blocks of about a second taken in turn (loop, play,
untraced play, ...), so the three see the same load. `ratio`: play's median over the loop's (the goal:
>= 0.7). `steps_per_cpu_s`, `cpu_ratio`: the same per CPU second of the process (all threads, the store
writer's too), which leaves out a busy machine's waits for a core.

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
from tracelab.bench.sims import SpecLoop
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.gridwar import scenario_spec
from tracelab.envs.declared.play import load_declared, make_declared_env, play_episodes, random_policy
from tracelab.envs.declared.vector_world import DeclaredWorlds
from tracelab.game.scenario import builtin_scenario
from tracelab.store import TraceWriter

GOAL_RATIO = 0.7
GOAL_PEAK_MB = 300
SCENARIO, SEED = "base", 1
MEMORY_SCENARIO, MEMORY_SEED = "advanced", 3


def _source(scenario: str) -> EnvSource:
    """The spec and params `tracelab play --scenario NAME` plays."""
    path, params = scenario_spec(builtin_scenario(scenario))
    return EnvSource(path, params)


def _env(source: EnvSource, run_dir: Path | None) -> Any:
    """The declared env `tracelab play` makes: into a new run at `run_dir` (its metadata as play writes it:
    the spec and its params; the recorder adds the board and the sources), or untraced."""
    spec = load_declared(source)
    if run_dir is None:
        return make_declared_env(source, spec)
    spec_path, params = source.declared()
    meta = {"command": "tracelab bench play", "rule_files": list(spec.program.files), "seed": SEED,
            "config": {"env": source.name, "env_id": None, "spec_path": spec_path, "env_args": params,
                       "policy": "random"}}
    return make_declared_env(source, spec, trace_writer=TraceWriter.open(run_dir, meta))


def _play(source: EnvSource, episodes: int, run_dir: Path | None) -> tuple[int, float, float]:
    """A `tracelab play` of `episodes` episodes (into a new run at `run_dir`, or untraced): (steps, wall and
    CPU seconds from after the env's build to the run closed)."""
    env = _env(source, run_dir)
    t0, c0 = time.perf_counter(), time.process_time()
    played = play_episodes(env, episodes, SEED, random_policy(env, SEED))
    env.close()  # a traced env closes its writer: the last rows and episode ends are written
    return played["steps"], time.perf_counter() - t0, time.process_time() - c0


def speed(repeats: int, target_s: float, tmp: Path) -> dict[str, Any]:
    """The loop, play traced and play untraced, one world, in turn (module docstring)."""
    source = _source(SCENARIO)
    loop = SpecLoop(DeclaredWorlds(load_declared(source), 1), True, seed=SEED)
    block = calibrate(loop.run, target_s)
    loop.run(block)  # warm-up at full size
    # episodes for a block of play: from a warm-up play, its steps per episode
    probe = 20
    steps, _, _ = _play(source, probe, tmp / "probe")
    episodes = max(1, int(probe * block / max(steps, 1)))
    names = ("loop", "play", "play_untraced")
    wall: dict[str, list[float]] = {name: [] for name in names}
    cpu: dict[str, list[float]] = {name: [] for name in names}
    for i in range(max(1, repeats)):
        t0, c0 = time.perf_counter(), time.process_time()
        loop.run(block)
        wall["loop"].append(block / (time.perf_counter() - t0))
        cpu["loop"].append(block / (time.process_time() - c0))
        for name, run_dir in (("play", tmp / f"run-{i}"), ("play_untraced", None)):
            steps, seconds, cpu_s = _play(source, episodes, run_dir)
            wall[name].append(steps / seconds)
            cpu[name].append(steps / cpu_s)
        shutil.rmtree(tmp / f"run-{i}", ignore_errors=True)
    out: dict[str, Any] = {"worlds": 1, "loop_steps": block, "play_episodes": episodes}
    for name in names:
        out[name] = {"steps_per_s": summarize(wall[name]).to_dict(),
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


def run(quick: bool = False, repeats: int = 5, memory_lengths: list[int] | None = None) -> dict[str, Any]:
    info = machine_info()
    target_s = 0.2 if quick else 1.0
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-play-") as tmp:
        rows = [speed(repeats, target_s, Path(tmp))]
    mem = [memory(n) for n in (memory_lengths or [])]
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "scenario": SCENARIO, "speed": rows,
            "memory": mem}


def report(r: dict[str, Any]) -> str:
    med = lambda d: d["steps_per_s"]["median"]  # noqa: E731
    sp = lambda d: f"{100 * d['steps_per_s']['spread']:.0f}%"  # noqa: E731
    cpu = lambda d: d["steps_per_cpu_s"]["median"]  # noqa: E731
    parts = [machine_line(r["machine"], r["quick"], r["repeats"]),
             f"play --scenario {r['scenario']} (red random) against bench env's traced loop, steps/s\n"
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
    tmp = Path(tempfile.mkdtemp(prefix="tracelab-bench-play-memory-"))
    try:
        env = _env(_source(MEMORY_SCENARIO), tmp / "run")
        samples: list[float] = []
        every, played = max(1, episodes // 10), [0]

        def counted(_: dict[str, Any]) -> None:
            played[0] += 1
            if played[0] % every == 0:
                samples.append(rss_bytes() / 2**20)
        t0 = time.perf_counter()
        play_episodes(env, episodes, MEMORY_SEED, random_policy(env, MEMORY_SEED), on_episode=counted)
        env.close()
        seconds = time.perf_counter() - t0
        run_mb = sum(f.stat().st_size for f in (tmp / "run").rglob("*") if f.is_file()) / 2**20
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"episodes": episodes, "rss_mb": samples, "peak_mb": high_water_bytes() / 2**20,
            "seconds": seconds, "run_mb": run_mb}


if __name__ == "__main__":
    print(json.dumps(_memory_child(int(sys.argv[1]))))
