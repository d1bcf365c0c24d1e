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

# run -> (env id, spec, value iteration's horizon, start resets, the metric plotted, evaluation games)
GAMES = {"frozenlake": ("tracelab/FrozenLake-v1", "frozen_lake.toml", 100, 1, "eval/success_rate", 10_000),
         "cliffwalking": ("tracelab/CliffWalking-v1", "cliff_walking.toml", 100, 1, "eval/mean_return", 100),
         "taxi": ("tracelab/Taxi-v4", "taxi.toml", 200, 3_000, "eval/mean_return", 3_000)}


def curve(run: Path, name: str) -> tuple[list[int], list[float]]:
    con = open_run(run)
    rows = con.sql(f"SELECT step, value FROM metrics WHERE name = '{name}' ORDER BY step").fetchall()
    con.close()
    return [r[0] for r in rows], [r[1] for r in rows]


def main(runs: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for ax, (game, (env, spec, horizon, starts, metric, games)) in zip(axes, GAMES.items()):
        # the start's value: exact with one start state; Taxi's from the starts of 3,000 seeded resets
        tr = enumerate_transitions(load_spec(spec_path(spec)), start_seeds=starts)
        optimal = optimal_start_value(tr, horizon)
        out = subprocess.run([sys.executable, "-m", "tracelab.cli", "eval", str(runs / game / "policy"), "--env",
                              env, "--games", str(games), "--seed", "12345", "--json"],
                             capture_output=True, text=True, check=True)
        ev = json.loads(out.stdout)
        print(f"{env}: value iteration over the rules ({len(tr.outcomes)} states): {optimal:.4f}; "
              f"trained policy over {games:,} games: mean return {ev['mean_return']:.4f}, success rate "
              f"{ev['success_rate']:.4f} {[round(x, 4) for x in ev['success_rate_ci95']]}, mean steps "
              f"{ev['mean_steps']:.1f}")
        steps, values = curve(runs / game, metric)
        ax.plot(steps, values, marker="o", label=f"DQN, greedy ({metric})")
        ax.axhline(optimal, color="black", linestyle="--", label=f"optimal by value iteration ({optimal:.3f})")
        if min(values) < -100:  # a greedy policy walking in circles until the 10,000-step cap
            ax.set_yscale("symlog")
        ax.set_title(env)
        ax.set_xlabel("training steps")
        ax.set_ylabel(metric)
        ax.legend(loc="best", fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out_png = Path(__file__).with_name("evaluations.png")
    fig.savefig(out_png, dpi=90)
    print(f"wrote {out_png}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
