"""`tracelab bench aggregates`: what quantifiers and annotation functions cost (docs/language.md).

(a) Registering a user annotation function: a plain Python function, and numba @njit functions (the first
    one in the process pays numba's start-up; registration compiles the function's one signature). The
    engine's kernels are never recompiled (the count of step_worlds' compiled signatures is reported).
(b) Rules evaluated per head grounding against their plain equivalents on the big-graph section's random
    graphs (tracelab/bench/biggraph.py: out-degree 5, 10 seeds, 11 steps, tracing on): the spread rule
    with Δt = 1 and with Δt = 0 (a fixpoint of many passes inside one step, where every head group is
    re-evaluated each pass), written plainly and as `[>= 1] infected(Y)` (the same meaning, so the same
    result is checked); a percentage; built-in and user-function averages.
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numba
import numpy as np

from tracelab.bench import biggraph
from tracelab.bench.common import format_table, summarize
from tracelab.engine import Engine, kernel as K, load_graphml, parse_program, register_annotation
from tracelab.engine.annotations import unregister_annotation

SIZES = (2_000, 20_000)
QUICK_SIZES = (2_000,)
RULES = {
    "spread Δt=1": "infected(X) <-1 infected(Y), link(Y,X)",
    "[>= 1] Δt=1": "infected(X) <-1 link(Y,X), [>= 1] infected(Y)",
    "spread Δt=0": "infected(X) <-0 infected(Y), link(Y,X)",
    "[>= 1] Δt=0": "infected(X) <-0 link(Y,X), [>= 1] infected(Y)",
    "[>= 40%] Δt=1": "infected(X) <-1 link(Y,X), [>= 40%] infected(Y)",
    "average Δt=1": "risk(X):average <-1 link(Y,X), infected(Y):[0,1] {weights=0,1}",
    "user average Δt=1": "risk(X):bench_average <-1 link(Y,X), infected(Y):[0,1] {weights=0,1}",
}
SAME_MEANING = (("spread Δt=1", "[>= 1] Δt=1"), ("spread Δt=0", "[>= 1] Δt=0"))


def _python_average(lower: np.ndarray, upper: np.ndarray, weights: np.ndarray) -> tuple[float, float]:
    return float(lower.mean()), float(upper.mean())


def _fresh_njit():
    """A new numba dispatcher each call (a registration compiles it)."""
    @numba.njit
    def njit_average(lower, upper, weights):
        return lower.mean(), upper.mean()
    return njit_average


def registration(repeats: int) -> dict[str, Any]:
    """Seconds per registration; the kernel's compiled signatures around registering and then running a
    rule with a fresh user function (loading the kernel from numba's cache first)."""
    Engine(parse_program("p(a)\nq(X) <-0 p(X)\n")).step()  # the kernel is loaded (or compiled) now
    before = len(K.step_worlds.signatures)
    python_s, njit_s = [], []
    for i in range(repeats):
        python_s.append(register_annotation(f"bench_py_{i}", _python_average))
        njit_s.append(register_annotation(f"bench_nb_{i}", _fresh_njit()))
    Engine(parse_program("p(a)\nq(X):bench_nb_0 <-0 p(X)\nr(X):bench_py_0 <-1 p(X)\n")).run(3)
    for i in range(repeats):
        unregister_annotation(f"bench_py_{i}")
        unregister_annotation(f"bench_nb_{i}")
    return {"python_s": summarize(python_s).to_dict(), "njit_first_s": njit_s[0],
            "njit_later_s": summarize(njit_s[1:] or njit_s).to_dict(),
            "kernel_signatures_before": before, "kernel_signatures_after": len(K.step_worlds.signatures)}


def rule_costs(sizes: tuple[int, ...], repeats: int) -> list[dict[str, Any]]:
    register_annotation("bench_average", _python_average)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = Path(tmp) / f"g{n}.graphml"
            biggraph.write_graph(path, n)
            graph = load_graphml(path)
            results: dict[str, dict[str, tuple[float, float]]] = {}
            Engine(parse_program(RULES["spread Δt=1"] + "\n"), graph).run(2)  # warm-up, not timed
            for name, rule in RULES.items():
                program = parse_program(rule + "\n", "bench.rules")
                build, run = [], []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    eng = Engine(program, graph, trace=True)
                    t1 = time.perf_counter()
                    eng.run(biggraph.STEPS)
                    t2 = time.perf_counter()
                    build.append(t1 - t0)
                    run.append(t2 - t1)
                results[name] = eng.interpretation(0)
                rows.append({"nodes": n, "rule": name, "build_s": summarize(build).to_dict(),
                             "run_s": summarize(run).to_dict(),
                             "set_atoms": len(results[name]), "passes": int(eng.stats["passes"][0])})
            for a, b in SAME_MEANING:
                if results[a] != results[b]:
                    raise AssertionError(f"{a} and {b} disagree on {n} nodes")
    return rows


def run(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    repeats = 1 if quick else repeats
    return {"registration": registration(max(repeats, 2)),
            "rules": rule_costs(QUICK_SIZES if quick else SIZES, repeats), "repeats": repeats}


def report(r: dict[str, Any]) -> str:
    reg = r["registration"]
    lines = [
        "registering a user annotation function (seconds; median [min-max]):",
        (f"  plain Python: {_med(reg['python_s'])}   numba @njit: first in the process "
         f"{reg['njit_first_s']:.3f}, later {_med(reg['njit_later_s'])}"),
        (f"  step_worlds compiled signatures: {reg['kernel_signatures_before']} before, "
         f"{reg['kernel_signatures_after']} after registering and running user functions (same: no recompile)"),
        "",
        f"rules on the big-graph graphs ({biggraph.STEPS} steps, tracing on, median of {r['repeats']}):",
    ]
    base = {(row["nodes"], row["rule"]): row["run_s"]["median"] for row in r["rules"]}
    table = []
    for row in r["rules"]:
        plain = "spread Δt=0" if "Δt=0" in row["rule"] else "spread Δt=1"
        ratio = row["run_s"]["median"] / base[(row["nodes"], plain)]
        table.append([f"{row['nodes']:,}", row["rule"], f"{row['build_s']['median'] * 1e3:.0f} ms",
                      f"{row['run_s']['median'] * 1e3:.0f} ms", f"{ratio:.1f}x", str(row["passes"]),
                      f"{row['set_atoms']:,}"])
    lines.append(format_table(["nodes", "rule", "build", "run", "vs plain", "passes", "atoms set"], table))
    return "\n".join(lines)


def _med(s: dict[str, float]) -> str:
    return f"{s['median']:.4f} [{s['min']:.4f}-{s['max']:.4f}]"
