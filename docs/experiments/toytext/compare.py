"""docs/experiments/toytext.md: the optimal tabular figures of each game by value iteration over the rules'
own transitions (tracelab/train/tabular.py), beside a trained policy's greedy evaluation, and the plot of
the three runs' evaluations.

    python docs/experiments/toytext/compare.py RUNS_DIR   # RUNS_DIR/{frozenlake,cliffwalking,taxi}
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from tracelab.envs.declared.spec import load_spec  # noqa: E402
from tracelab.envs.declared.toytext import spec_path  # noqa: E402
from tracelab.store.reader import open_run  # noqa: E402
from tracelab.train.tabular import enumerate_transitions, optimal_start_value  # noqa: E402

GAMES = {"frozenlake": ("tracelab/FrozenLake-v1", "frozen_lake.toml", 100, "eval/success_rate", 10_000),
         "cliffwalking": ("tracelab/CliffWalking-v1", "cliff_walking.toml", 100, "eval/mean_return", 100),
         "taxi": ("tracelab/Taxi-v4", None, None, "eval/mean_return", 1_000)}


def curve(run: Path, name: str) -> tuple[list[int], list[float]]:
    con = open_run(run)
    rows = con.sql(f"SELECT step, value FROM metrics WHERE name = '{name}' ORDER BY step").fetchall()
    con.close()
    return [r[0] for r in rows], [r[1] for r in rows]


def main(runs: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for ax, (game, (env, spec, horizon, metric, games)) in zip(axes, GAMES.items()):
        optimal = None
        if spec is not None:
            optimal = optimal_start_value(enumerate_transitions(load_spec(spec_path(spec))), horizon)
        out = subprocess.run([sys.executable, "-m", "tracelab.cli", "eval", str(runs / game / "policy"), "--env",
                              env, "--games", str(games), "--seed", "12345", "--json"],
                             capture_output=True, text=True, check=True)
        ev = json.loads(out.stdout)
        print(f"{env}: value iteration over the rules: {optimal if optimal is None else round(optimal, 4)}; "
              f"trained policy over {games:,} games: mean return {ev['mean_return']:.4f}, success rate "
              f"{ev['success_rate']:.4f} {[round(x, 4) for x in ev['success_rate_ci95']]}, mean steps "
              f"{ev['mean_steps']:.1f}")
        steps, values = curve(runs / game, metric)
        ax.plot(steps, values, marker="o", label=f"DQN, greedy ({metric})")
        if optimal is not None:
            ax.axhline(optimal, color="black", linestyle="--",
                       label=f"optimal by value iteration ({optimal:.3f})")
        ax.set_title(env)
        ax.set_xlabel("training steps")
        ax.set_ylabel(metric)
        ax.legend(loc="lower right")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out_png = Path(__file__).with_name("evaluations.png")
    fig.savefig(out_png, dpi=90)
    print(f"wrote {out_png}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
