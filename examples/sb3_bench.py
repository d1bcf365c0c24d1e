"""What logging into a tracelab run costs a Stable-Baselines3 training (docs/benchmarks/history.md, "Stable-Baselines3
callback"): PPO's steps per second on an env without the callback, with it logging only (one 1-game
evaluation at the end), and with it evaluating as by default (every 10,000 steps, 50 games, 5 traced);
the three interleaved `--repeats` times in one process, the median of each, per wall second and per CPU
second.

    python examples/sb3_bench.py --env tracelab/GridWar-base-v0 --steps 20480 --repeats 3"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import torch
from stable_baselines3 import PPO
from tracelab.train.sb3 import TracelabCallback, make_vec_env  # an id or a spec file

SETUPS = {"no callback": None, "callback, logging only": {"eval_every": 0, "eval_games": 1, "trace_eval_games": 0},
          "callback, evaluating (default)": {}}


def one(env_id: str, steps: int, n_envs: int, options: dict | None, run: Path) -> tuple[float, float]:
    """Steps per second of one PPO learn() (the model built beforehand, not timed): per wall second, and
    per CPU second of the process (every thread: the run's writer flushes in its own), which a machine
    shared with other work changes less."""
    model = PPO("MlpPolicy", make_vec_env(env_id, n_envs=n_envs, seed=0), n_steps=256, batch_size=256, seed=0,
                device="cpu")
    t0, c0 = time.perf_counter(), time.process_time()
    if options is None:
        model.learn(steps)
    else:
        with TracelabCallback(run, env_id, **options) as cb:
            model.learn(steps, callback=cb)
    return steps / (time.perf_counter() - t0), steps / (time.process_time() - c0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="tracelab/GridWar-base-v0")
    p.add_argument("--steps", type=int, default=20_480)
    p.add_argument("--n-envs", type=int, default=8)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    torch.set_num_threads(1)
    rates: dict[str, list[tuple[float, float]]] = {k: [] for k in SETUPS}
    with tempfile.TemporaryDirectory() as tmp:
        one(args.env, 2048, args.n_envs, SETUPS["callback, evaluating (default)"], Path(tmp) / "warm")  # compiles
        for r in range(args.repeats):
            for k, (name, options) in enumerate(SETUPS.items()):
                rates[name].append(one(args.env, args.steps, args.n_envs, options, Path(tmp) / f"run-{r}-{k}"))
    for name, values in rates.items():
        wall, cpu = [v[0] for v in values], [v[1] for v in values]
        print(f"{name:32s} median {statistics.median(wall):6.0f} steps/s ({', '.join(f'{v:.0f}' for v in wall)}), "
              f"{statistics.median(cpu):6.0f} steps per CPU s ({', '.join(f'{v:.0f}' for v in cpu)})")


if __name__ == "__main__":
    main()
