"""Benchmark of the trace store: ingest rate through TraceWriter, sealing rate, point-query latency.

store_benchmark() is what a `bench store` command calls; synthetic_* make engine-format data."""
from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.store.reader import open_run
from tracelab.store.seal import seal_run
from tracelab.store.writer import TraceWriter


def synthetic_vocabulary(n_nodes: int = 64, n_atoms: int = 1000) -> dict[str, Any]:
    """A vocabulary in Engine.vocabulary()'s format: labels p/1 and q/2 over nodes n0.."""
    rng = np.random.default_rng(0)
    return {"nodes": [f"n{i}" for i in range(n_nodes)], "labels": ["p", "q"],
            "label_arity": np.array([1, 2], np.int8),
            "atom_label": (np.arange(n_atoms) % 2).astype(np.int32),
            "atom_arg0": rng.integers(0, n_nodes, n_atoms).astype(np.int32),
            "atom_arg1": np.where(np.arange(n_atoms) % 2 == 1,
                                  rng.integers(0, n_nodes, n_atoms), -1).astype(np.int32)}


def synthetic_trace(n: int, n_atoms: int = 1000, t0: int = 0, world: int = 0,
                    seed: int = 0) -> dict[str, np.ndarray]:
    """n rows in Engine.take_trace()'s format over timesteps t0.. (10 rows a step), caused by facts and
    actions only, so no grounding table is needed."""
    rng = np.random.default_rng(seed)
    return {
        "world": np.full(n, world, np.int32),
        "t": (t0 + np.arange(n) // 10).astype(np.int32),
        "pass_no": np.zeros(n, np.int32),
        "atom": rng.integers(0, n_atoms, n).astype(np.int32),
        "cause_kind": rng.integers(0, 2, n).astype(np.int8),
        "cause_id": rng.integers(0, 5, n).astype(np.int32),
        "grounding": np.full(n, -1, np.int32),
        "n_sources": np.ones(n, np.int16),
        "old_lower": np.zeros(n), "old_upper": np.ones(n),
        "new_lower": rng.integers(0, 2, n).astype(np.float64), "new_upper": np.ones(n),
    }


def _ingest_once(run_dir: Path, batches: list[dict[str, np.ndarray]], episode_rows: int) -> float:
    """Seconds from the first write to close() returning (every row published as Parquet)."""
    vocab = synthetic_vocabulary()
    start = time.perf_counter()
    with TraceWriter(run_dir, {"command": "bench store"}) as w:
        w.write_vocabulary(vocab)
        written, episode = 0, 0
        w.begin_episode(episode)
        for b in batches:
            written += w.write_changes(episode, b)
            if written >= (episode + 1) * episode_rows:
                w.end_episode(episode, steps=200, outcome="win")
                episode += 1
                w.begin_episode(episode)
        w.end_episode(episode, steps=200, outcome="win")
    return time.perf_counter() - start


def store_benchmark(rows: int = 2_000_000, batch: int = 50_000, repeats: int = 3,
                    directory: str | Path | None = None) -> dict[str, Any]:
    """Ingest `rows` change rows in batches of `batch` (an engine's take_trace() every few steps) through
    TraceWriter, `repeats` times; report the median rows/s, then seal the last run and time a point
    query (one episode, six timesteps) on the live and the sealed form."""
    batches = [synthetic_trace(batch, t0=i * (batch // 10), seed=i) for i in range(max(1, rows // batch))]
    total = batch * len(batches)
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        times = [_ingest_once(Path(tmp) / f"run{i}", batches, episode_rows=20_000) for i in range(repeats)]
        run = Path(tmp) / f"run{repeats - 1}"
        point = "SELECT * FROM changes WHERE episode = 42 AND t BETWEEN 16 AND 21"
        live_ms = _query_ms(run, point)
        t0 = time.perf_counter()
        seal_run(run)
        seal_s = time.perf_counter() - t0
        sealed_ms = _query_ms(run, point)
    rates = [total / t for t in times]
    return {"rows": total, "batch": batch, "ingest_rows_per_s": statistics.median(rates),
            "ingest_rows_per_s_runs": rates, "seal_rows_per_s": total / seal_s,
            "point_query_ms_live": live_ms, "point_query_ms_sealed": sealed_ms}


def _query_ms(run: Path, sql: str, repeats: int = 5) -> float:
    con = open_run(run)
    con.execute(sql).fetchall()
    t0 = time.perf_counter()
    for _ in range(repeats):
        con.execute(sql).fetchall()
    con.close()
    return (time.perf_counter() - t0) / repeats * 1000


if __name__ == "__main__":
    for k, v in store_benchmark().items():
        print(f"{k}: {v}")
