"""A writer process for the store's live-reading and crash tests: `python store_proc.py MODE RUN_DIR`.

live    write episodes 0..N-1 (N = argv[3]) in small chunks, relying on the writer's own flushing;
        prints `ended E` after each end_episode
crash   write episodes forever; after each end_episode + flush() prints `committed E`
idle    write 500 rows of episode 0 without flushing, print `wrote`, then sleep (the timer must flush)"""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from store_helpers import episode_rows, synthetic_trace, synthetic_vocabulary  # noqa: E402

from tracelab.store.writer import TraceWriter  # noqa: E402


def write_episode(w: TraceWriter, e: int, chunks: int, pause: float) -> None:
    w.begin_episode(e, t_start=0)
    rows = synthetic_trace(episode_rows(e), seed=e)
    bounds = [round(i * len(rows["t"]) / chunks) for i in range(chunks + 1)]
    for lo, hi in zip(bounds, bounds[1:]):
        w.write_changes(e, {k: v[lo:hi] for k, v in rows.items()})
        time.sleep(pause)
    w.write_steps(e, {"step": range(5), "action": [1, 2, 3, 4, 0], "reward": [-2.0] * 5, "agent": "red"})
    w.end_episode(e, steps=5, outcome="win" if e % 2 else "loss", reward=float(e))


def main(mode: str, run_dir: str, *rest: str) -> None:
    if mode == "live":
        with TraceWriter(run_dir, {"command": "store_proc live"}, flush_interval=0.1, part_rows=4000,
                         compact_files=4) as w:
            w.write_vocabulary(synthetic_vocabulary())
            for e in range(int(rest[0])):
                write_episode(w, e, chunks=3, pause=0.03)
                print(f"ended {e}", flush=True)
    elif mode == "crash":
        w = TraceWriter(run_dir, {"command": "store_proc crash"}, flush_interval=0.2, part_rows=3000,
                        compact_files=3)
        w.write_vocabulary(synthetic_vocabulary())
        e = 0
        while True:
            write_episode(w, e, chunks=4, pause=0.005)
            w.flush()
            print(f"committed {e}", flush=True)
            e += 1
    elif mode == "idle":
        w = TraceWriter(run_dir, {"command": "store_proc idle"})  # default flush_interval: 1 s
        w.write_vocabulary(synthetic_vocabulary())
        w.begin_episode(0)
        w.write_changes(0, synthetic_trace(500))
        print("wrote", flush=True)
        threading.Event().wait()  # idle until killed: only the writer's own timer can publish the rows
    else:
        raise SystemExit(f"unknown mode {mode!r}")


if __name__ == "__main__":
    main(*sys.argv[1:])
