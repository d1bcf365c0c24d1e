"""`tracelab bench toytext`: gymnasium's toy-text games written as rules (rules/toytext/, docs/worlds.md)
against gymnasium's own pure-Python envs, one world each, untraced, in one run.

Both envs are stepped unwrapped (no TimeLimit or checker wrappers) with the same fixed random actions,
reset when an episode ends, so a figure includes the resets a random policy makes (FrozenLake 4x4
resets every ~8 steps). The issue's goal for one world is a ratio of at least 0.5; and the same env
traced into the store (tracelab/envs/declared/recording.py) at least 0.5x itself untraced. The traced and
untraced env take their timed blocks in turn (so both see the same load), timed in wall-clock and in CPU
seconds of the process (the store writer's thread included: the steadier figure on a busy machine)."""
from __future__ import annotations

import tempfile
import time
from typing import Any

import gymnasium as gym
import numpy as np

import tracelab.envs  # noqa: F401  (registers the ids)
from tracelab.bench import toytext_vector
from tracelab.bench.common import block_rates, calibrate, format_table, summarize
from tracelab.store import TraceWriter

GOAL_RATIO = 0.5
TARGET_S = 0.5  # a timed block
GAMES = (("FrozenLake 4x4", "tracelab/FrozenLake-v1", "FrozenLake-v1", {}),
         ("FrozenLake 8x8 dry", "tracelab/FrozenLake-v1", "FrozenLake-v1", {"map_name": "8x8", "is_slippery": False}),
         ("CliffWalking", "tracelab/CliffWalking-v1", "CliffWalking-v1", {}),
         ("Taxi", "tracelab/Taxi-v4", "Taxi-v4", {}))


def stepper(env: gym.Env) -> Any:
    """run(k): k steps of fixed random actions, resetting as episodes end."""
    actions = np.random.default_rng(0).integers(env.action_space.n, size=1 << 16).tolist()
    env.reset(seed=0)
    where = [0]

    def run(k: int) -> None:
        i = where[0]
        for _ in range(k):
            _, _, terminated, truncated, _ = env.step(actions[i])
            i = (i + 1) & 0xFFFF
            if terminated or truncated:
                env.reset()
        where[0] = i
    return run


def run(quick: bool = False, repeats: int = 5, batch: int | None = None) -> dict[str, Any]:
    repeats = 1 if quick else repeats
    target = 0.05 if quick else TARGET_S
    out = []
    for name, ours_id, theirs_id, kwargs in GAMES:
        theirs = block_rates(stepper(gym.make(theirs_id, **kwargs).unwrapped), repeats, target)
        ours, traced = traced_and_untraced_rates(ours_id, kwargs, repeats, target)
        ratio = ours["steps_per_s"]["median"] / theirs["steps_per_s"]["median"]
        traced_ratio = traced["steps_per_s"]["median"] / ours["steps_per_s"]["median"]
        traced_cpu_ratio = traced["steps_per_cpu_s"]["median"] / ours["steps_per_cpu_s"]["median"]
        out.append({"game": name, "tracelab": ours, "gymnasium": theirs, "ratio": ratio,
                    "goal_met": ratio >= GOAL_RATIO, "traced": traced, "traced_ratio": traced_ratio,
                    "traced_cpu_ratio": traced_cpu_ratio, "traced_goal_met": traced_ratio >= GOAL_RATIO})
    vector = toytext_vector.run(batch or (16 if quick else 256), quick, repeats)
    return {"games": out, "goal_ratio": GOAL_RATIO, "repeats": repeats, "vector": vector}


def traced_and_untraced_rates(env_id: str, kwargs: dict[str, Any], repeats: int, target: float
                              ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The env untraced, and the same env recording every game into a run of the trace store (a
    temporary directory), their timed blocks in turn; the writer's close (its last rows) timed apart."""
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-toytext-") as tmp:
        env = gym.make(env_id, trace_writer=TraceWriter.open(f"{tmp}/run"), **kwargs).unwrapped
        runs = {"untraced": stepper(gym.make(env_id, **kwargs).unwrapped), "traced": stepper(env)}
        blocks = {name: calibrate(run, target) for name, run in runs.items()}
        wall: dict[str, list[float]] = {name: [] for name in runs}
        cpu: dict[str, list[float]] = {name: [] for name in runs}
        for _ in range(max(1, repeats) + 1):  # the first round is a warm-up at full size
            for name, run in runs.items():
                t0, c0 = time.perf_counter(), time.process_time()
                run(blocks[name])
                wall[name].append(blocks[name] / (time.perf_counter() - t0))
                cpu[name].append(blocks[name] / max(time.process_time() - c0, 1e-9))
        out = {name: {"steps_per_repeat": blocks[name], "steps_per_s": summarize(wall[name][1:]).to_dict(),
                      "steps_per_cpu_s": summarize(cpu[name][1:]).to_dict()} for name in runs}
        t0 = time.perf_counter()
        env.close()
        out["traced"]["close_s"] = time.perf_counter() - t0
    return out["untraced"], out["traced"]


def report(r: dict[str, Any]) -> str:
    rows, traced_rows = [], []
    for g in r["games"]:
        ours, theirs = g["tracelab"]["steps_per_s"]["median"], g["gymnasium"]["steps_per_s"]["median"]
        rows.append([g["game"], f"{ours:,.0f}", f"{1e6 / ours:.1f}", f"{theirs:,.0f}", f"{1e6 / theirs:.1f}",
                     f"{g['ratio']:.2f}", "yes" if g["goal_met"] else "no"])
        traced = g["traced"]["steps_per_s"]["median"]
        traced_rows.append([g["game"], f"{traced:,.0f}", f"{1e6 / traced:.1f}", f"{ours:,.0f}",
                            f"{g['traced_ratio']:.2f}", f"{g['traced_cpu_ratio']:.2f}", f"{g['traced']['close_s']:.2f}",
                            "yes" if g["traced_goal_met"] else "no"])
    head = (f"one world, untraced, random actions with resets (median of {r['repeats']}); "
            f"goal: tracelab >= {r['goal_ratio']}x gymnasium")
    traced_head = (f"the same, traced into a run of the store (every change, step and game), blocks in turn with "
                   f"untraced ones; goal: traced >= "
                   f"{r['goal_ratio']}x untraced")
    return (head + "\n" + format_table(["game", "tracelab steps/s", "us/step", "gymnasium steps/s", "us/step",
                                        "ratio", "goal"], rows) + "\n\n" + traced_head + "\n" +
            format_table(["game", "traced steps/s", "us/step", "untraced steps/s", "ratio", "CPU ratio", "close s",
                          "goal"],
                         traced_rows) + "\n\n" + toytext_vector.report(r["vector"]))
