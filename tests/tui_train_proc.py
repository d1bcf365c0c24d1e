"""A training-run writer for the TUI's live-curve test: `python tui_train_proc.py RUN_DIR STOP_FILE`.

Follows the training-run contract (HELPER_GUIDE): meta command `tracelab train ...`, training episodes
with begin info {"kind": "train", "train_step": N}, `metrics` rows (loss, epsilon, train_return,
eval/win_rate). Writes one batch of metrics every 0.2 s, flushes, prints `step N`, until STOP_FILE exists."""
from __future__ import annotations

import sys
import time
from pathlib import Path

from tracelab.store.writer import TraceWriter


def main(run_dir: str, stop_file: str) -> None:
    with TraceWriter(run_dir, {"command": "tracelab train --test", "config": {"test": True}},
                     flush_interval=0.1) as w:
        step, episode = 0, 0
        while not Path(stop_file).exists() and step < 5_000:
            step += 100
            w.begin_episode(episode, info={"kind": "train", "train_step": step})
            w.end_episode(episode, steps=10, outcome="win" if episode % 3 == 0 else "loss", reward=1.0)
            w.write_metrics(step, {"loss": 1.0 / (1 + step / 100), "epsilon": max(0.05, 1 - step / 2000),
                                   "train_return": step / 100.0})
            if step % 300 == 0:
                w.write_metrics(step, {"eval/win_rate": min(1.0, step / 3000)})
            w.flush()
            print(f"step {step}", flush=True)
            episode += 1
            time.sleep(0.2)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
