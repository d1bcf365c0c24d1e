"""`tracelab bench toytext`, the batched part: N worlds of a toy-text game in tracelab's vector env (one engine,
tracelab/envs/declared/vector_env.py) against gymnasium's SyncVectorEnv of gymnasium's own game, both with
SAME_STEP autoreset and the registered step limit, stepped with the same fixed random actions. Figures are
env-steps/s (worlds x vector steps), medians of the timed blocks. The issue's goal: at least 5x."""
from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import tracelab.envs  # noqa: F401  (registers the ids)
from tracelab.bench.common import block_rates, format_table

GOAL_RATIO = 5.0
TARGET_S = 0.5
GAMES = (("FrozenLake 4x4 slippery", "tracelab/FrozenLake-v1", "FrozenLake-v1", {}),
         ("CliffWalking", "tracelab/CliffWalking-v1", "CliffWalking-v1", {}),
         ("Taxi", "tracelab/Taxi-v4", "Taxi-v4", {}))


def vector_stepper(env: gym.vector.VectorEnv) -> Any:
    """run(k): k vector steps of fixed random actions (the env resets worlds itself)."""
    n = env.single_action_space.n
    actions = np.random.default_rng(0).integers(n, size=(256, env.num_envs))
    env.reset(seed=0)
    where = [0]

    def run(k: int) -> None:
        i = where[0]
        for _ in range(k):
            env.step(actions[i])
            i = (i + 1) & 0xFF
        where[0] = i
    return run


def run(batch: int, quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    target = 0.05 if quick else TARGET_S
    out = []
    for name, ours_id, theirs_id, kwargs in GAMES:
        ours = gym.make_vec(ours_id, num_envs=batch, vectorization_mode="vector_entry_point", **kwargs)
        theirs = gym.make_vec(theirs_id, num_envs=batch, vectorization_mode="sync",
                              vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP}, **kwargs)
        rates = [block_rates(vector_stepper(env), repeats, target)["steps_per_s"] for env in (ours, theirs)]
        for r in rates:  # vector steps/s to env-steps/s (the spread is a ratio: unchanged)
            r.update(median=r["median"] * batch, min=r["min"] * batch, max=r["max"] * batch,
                     runs=[v * batch for v in r["runs"]])
        ratio = rates[0]["median"] / rates[1]["median"]
        out.append({"game": name, "tracelab": rates[0], "gymnasium": rates[1], "ratio": ratio,
                    "goal_met": ratio >= GOAL_RATIO})
    return {"games": out, "batch": batch, "goal_ratio": GOAL_RATIO, "repeats": repeats}


def report(r: dict[str, Any]) -> str:
    rows = [[g["game"], f"{g['tracelab']['median']:,.0f}", f"{g['gymnasium']['median']:,.0f}", f"{g['ratio']:.1f}",
             "yes" if g["goal_met"] else "no"] for g in r["games"]]
    head = (f"{r['batch']} worlds: tracelab's vector env (one engine) against gymnasium's SyncVectorEnv, "
            f"SAME_STEP autoreset, env-steps/s (median of {r['repeats']}); goal: >= {r['goal_ratio']:g}x")
    return head + "\n" + format_table(["game", "tracelab env-steps/s", "gymnasium env-steps/s", "ratio", "goal"],
                                      rows)
