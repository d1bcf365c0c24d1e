"""`tracelab bench engine`'s "big graph" section: the engine on PyReason-sized graphs.

A random directed graph (each node links to `OUT_DEGREE` random nodes) is written as GraphML, with
`infected` set on `SEEDS` nodes, and the spread rule `infected(X) <-1 infected(Y), link(Y,X)` runs for
`STEPS` steps with tracing on. Each size runs in a fresh child process (`python -m tracelab.bench.biggraph
FILE`), so that its peak resident memory is its own: load (GraphML -> columns), build (Engine(...)),
run(STEPS) and the trace rows are timed there.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from tracelab.bench.common import format_table, rss_bytes, summarize

OUT_DEGREE = 5
SEEDS = 10
STEPS = 11
SPREAD_RULE = "spread: infected(X) <-1 infected(Y), link(Y,X)\n"
SIZES = (2_000, 20_000, 200_000)
QUICK_SIZES = (2_000, 20_000)
# the measurements of PyReason 3.x on the same rule and graphs (11 steps), for the table
PYREASON_S = {250: 3.6, 2_000: 268.0}


def write_graph(path: Path, nodes: int, seed: int = 0) -> int:
    """Write the random graph as GraphML; returns the number of facts it holds (edges + seeds)."""
    rng = np.random.default_rng(seed)
    src = np.repeat(np.arange(nodes), OUT_DEGREE)
    dst = rng.integers(0, nodes, len(src))
    seeds = set(rng.choice(nodes, min(SEEDS, nodes), replace=False).tolist())
    with open(path, "w", encoding="utf-8") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n<graphml xmlns="http://graphml.graphdrawing.org/xmlns">\n'
                '<key id="d0" for="node" attr.name="infected" attr.type="boolean"/>\n'
                '<key id="d1" for="edge" attr.name="link" attr.type="boolean"/>\n'
                '<graph edgedefault="directed">\n')
        f.write("".join(f'<node id="n{i}"><data key="d0">true</data></node>\n' if i in seeds else
                        f'<node id="n{i}"/>\n' for i in range(nodes)))
        for lo in range(0, len(src), 100_000):
            f.write("".join(f'<edge source="n{s}" target="n{t}"><data key="d1">true</data></edge>\n'
                            for s, t in zip(src[lo:lo + 100_000].tolist(), dst[lo:lo + 100_000].tolist())))
        f.write("</graph>\n</graphml>\n")
    return len(src) + len(seeds)


def measure(graph_file: str) -> dict[str, Any]:
    """In this process: load, build, run; times, trace rows and peak RSS (call in a fresh process)."""
    # deferred: the engine loads numba, which bench engine's other importers (machine_line) do not need
    from tracelab.engine import Engine, load_graphml, parse_program

    program = parse_program(SPREAD_RULE, "spread.rules")
    # the compiled code loads from numba's cache on first use (~1-2 s, once per process): timed apart
    tw = time.perf_counter()
    warm = Path(graph_file).with_suffix(".warm.graphml")
    write_graph(warm, 20)
    Engine(program, load_graphml(warm), trace=True).run(2)
    warm_s = time.perf_counter() - tw
    base = rss_bytes()
    t0 = time.perf_counter()
    graph = load_graphml(graph_file)
    t1 = time.perf_counter()
    engine = Engine(program, graph, trace=True)
    t2 = time.perf_counter()
    rows = 0
    for _ in range(STEPS):
        engine.step()
        rows += len(engine.take_trace()["t"])
    t3 = time.perf_counter()
    infected = int(np.sum(engine.lower[0][engine.vocab.atom_label == engine.vocab.label_ids["infected"]] == 1.0))
    return {"nodes": len(graph.nodes), "facts": graph.n_facts, "atoms": engine.vocab.n_atoms,
            "groundings": int(engine._n_grounded), "load_s": t1 - t0, "build_s": t2 - t1, "run_s": t3 - t2,
            "trace_rows": rows, "infected": infected, "warm_up_s": warm_s, "base_rss_bytes": base,
            "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}


def run(quick: bool, repeats: int) -> list[dict[str, Any]]:
    """Every size, `repeats` fresh processes each; medians with spread, throughput and bytes per fact."""
    out = []
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-graph-") as tmp:
        for nodes in QUICK_SIZES if quick else SIZES:
            path = Path(tmp) / f"g{nodes}.graphml"
            write_graph(path, nodes)
            runs = [_child(str(path)) for _ in range(max(1, repeats))]
            row: dict[str, Any] = {k: runs[0][k] for k in ("nodes", "facts", "atoms", "groundings",
                                                             "trace_rows", "infected")}
            row["file_bytes"] = os.path.getsize(path)
            for k in ("load_s", "build_s", "run_s", "peak_rss_bytes", "base_rss_bytes", "warm_up_s"):
                row[k] = summarize([r[k] for r in runs]).to_dict()
            row["facts_per_s"] = summarize([r["facts"] / r["load_s"] for r in runs]).to_dict()
            # what the graph adds: peak minus the process before loading it (Python, numpy, numba, warm-up)
            row["bytes_per_fact"] = (row["peak_rss_bytes"]["median"] - row["base_rss_bytes"]["median"]) / row["facts"]
            row["pyreason_s"] = PYREASON_S.get(nodes)
            out.append(row)
    return out


GOALS = {"load_s": 5.0, "build_s": 5.0, "peak_rss_bytes": 1 << 30, "facts_per_s": 500_000, "bytes_per_fact": 300}


def report(rows: list[dict[str, Any]]) -> str:
    """The big-graph table, with PyReason's figures and the goals (for the 1M-edge graph)."""
    med = lambda d: d["median"]  # noqa: E731
    table = format_table(
        ["nodes / edges", "load s", "build s", f"run({STEPS}) s", "peak RSS MB", "base MB", "facts/s",
         "B/fact", "trace rows", "PyReason s"],
        [[f"{r['nodes']:,} / {r['facts'] - SEEDS:,}", med(r["load_s"]), med(r["build_s"]), med(r["run_s"]),
          med(r["peak_rss_bytes"]) / 2**20, med(r["base_rss_bytes"]) / 2**20, med(r["facts_per_s"]),
          r["bytes_per_fact"], r["trace_rows"],
          r["pyreason_s"] if r["pyreason_s"] is not None else "-"] for r in rows])
    big = rows[-1]
    checks = [("load <= 5 s", med(big["load_s"]) <= GOALS["load_s"]),
              ("build <= 5 s", med(big["build_s"]) <= GOALS["build_s"]),
              ("peak <= 1 GB", med(big["peak_rss_bytes"]) <= GOALS["peak_rss_bytes"]),
              (">= 500k facts/s", med(big["facts_per_s"]) >= GOALS["facts_per_s"]),
              ("<= 300 B/fact", big["bytes_per_fact"] <= GOALS["bytes_per_fact"])]
    goals = ", ".join(f"{name}: {'met' if ok else 'NOT met'}" for name, ok in checks)
    return (f"big graph: {SPREAD_RULE.strip()}, out-degree {OUT_DEGREE}, {SEEDS} seeds, tracing on; "
            f"one fresh process per run, after a warm-up on a 20-node graph (compiled code loads from "
            f"numba's cache: {med(big['warm_up_s']):.2f} s); B/fact = (peak - base) / facts\n{table}\n"
            f"goals at {big['facts'] - SEEDS:,} edges: {goals}")


def _child(graph_file: str) -> dict[str, Any]:
    proc = subprocess.run([sys.executable, "-m", "tracelab.bench.biggraph", graph_file], capture_output=True,
                          text=True, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"big-graph bench child failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    print(json.dumps(measure(sys.argv[1])), flush=True)
