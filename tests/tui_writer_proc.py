"""Live runs for the TUI's tests: `python tui_writer_proc.py MODE RUN_DIR STOP_FILE`, writing until STOP_FILE
exists (at most ~1000 rounds), one round every 0.2 s, each flushed and announced on stdout.

train  the training-run contract (HELPER_GUIDE): meta command `tracelab train ...`, training episodes with
       begin info {"kind": "train", "train_step": N}, `metrics` rows (loss, epsilon, train_return,
       eval/win_rate); prints `step N`
trace  episode 0 growing: 50 synthetic change rows a round (tracelab.store.bench's format); prints
       `rows N`
Ctrl-C stops it at the end of a round, as `tracelab train` stops at the end of a step (CtrlCBetweenSteps):
a KeyboardInterrupt raised wherever the handler happened to run could be swallowed (the process then wrote
on until its cap, and the TUI test waiting 30 s for it to end failed on a loaded machine)."""
from __future__ import annotations

import sys
import time
from pathlib import Path

from tracelab.commands._interrupt import CtrlCBetweenSteps
from tracelab.store.writer import TraceWriter


def trace(run_dir: str, stop_file: str) -> None:
    from tracelab.store.bench import synthetic_trace, synthetic_vocabulary
    with TraceWriter(run_dir, {"command": "tui test trace"}, flush_interval=0.1) as w, CtrlCBetweenSteps() as ctrl_c:
        w.write_vocabulary(synthetic_vocabulary())
        w.begin_episode(0, t_start=0)
        rows = 0
        while not Path(stop_file).exists() and rows < 50_000:
            rows += w.write_changes(0, synthetic_trace(50, t0=rows // 10, seed=rows))
            w.flush()
            print(f"rows {rows}", flush=True)
            time.sleep(0.2)
            ctrl_c.check()


def train(run_dir: str, stop_file: str) -> None:
    with TraceWriter(run_dir, {"command": "tracelab train --test", "config": {"test": True}},
                     flush_interval=0.1) as w, CtrlCBetweenSteps() as ctrl_c:
        step, episode = 0, 0
        # the stop file ends it; the cap (~2 min of rounds) only bounds a test that never touches it: at 5,000
        # steps (~10 s) a TUI test on a loaded machine once sent its Ctrl-C to a training already finished
        while not Path(stop_file).exists() and step < 60_000:
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
            ctrl_c.check()


if __name__ == "__main__":
    {"train": train, "trace": trace}[sys.argv[1]](sys.argv[2], sys.argv[3])
