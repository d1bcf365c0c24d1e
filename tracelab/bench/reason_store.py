"""`tracelab bench reason-store`: what recording a reasoning into the trace store costs, `reason --run`
against `reason --no-trace`, on the big-graph bench's 1M-edge graph (tracelab/bench/biggraph.py: 200k
nodes, out-degree 5, the spread rule, 11 steps; `--quick`: 20k nodes).

In one process, after a warm-up of both on a small graph, the two alternate `repeats` times; each is what
the command does without its printing (tracelab.reasoning): load the GraphML, build the engine, step it,
and for --run record everything into a new run (program, facts, vocabulary, groundings, edges, change
rows) and close it. Figures (medians): the wall time of each and their ratio; the change rows and how
fast the store took them (rows / the writer thread's time writing the `changes` parts, and every
table's rows / its time); the CPU time of all threads (steadier than wall time on a shared machine:
the writer's thread runs beside the reasoning); the main thread's time inside the recorder and at close
(what the reasoning waited for the store); the run's size on disk. Peak resident memory: of each mode
in a fresh process of its own (`python -m tracelab.bench.reason_store`, VmHWM), since in one process a
run starts from what the runs before it left in the allocator's heap; and in this process, sampled
every 10 ms, what each run added to the resident memory it started from."""
from __future__ import annotations

import gc
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from tracelab.bench.biggraph import OUT_DEGREE, SPREAD_RULE, STEPS, write_graph
from tracelab.bench.common import format_table, high_water_bytes, machine_info, rss_bytes, summarize
from tracelab.engine.memory import BIG_WORK, release_freed_memory
from tracelab.reasoning import EpisodeRun, load_inputs, open_reasoning_run, plan_episodes
from tracelab.store.reasoning import ReasoningRecorder

NODES, QUICK_NODES = 200_000, 20_000
GOAL_RATIO = 1.5            # reason --run <= 1.5x reason --no-trace
GOAL_ROWS_PER_S = 1_000_000  # change rows into the store


class PeakRss:
    """The highest resident set size seen while the block runs (a thread samples it)."""

    def __init__(self, every_s: float = 0.01) -> None:
        self.every_s, self.peak = every_s, 0
        self._stop = threading.Event()

    def _sample(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, rss_bytes())
            self._stop.wait(self.every_s)

    def __enter__(self) -> PeakRss:
        self.peak = rss_bytes()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, rss_bytes())


def reason_once(rules: Path, graph: Path, run_dir: Path | None) -> dict[str, Any]:
    """One reasoning as `tracelab reason RULES --graph GRAPH --steps 11` does it, recorded into
    `run_dir` (as with --run) or not traced at all (as with --no-trace)."""
    gc.collect()
    release_freed_memory(BIG_WORK)  # what the run before left in the heap: back to the system
    out: dict[str, Any] = {"base_rss_bytes": rss_bytes()}
    with PeakRss() as rss:
        t0, cpu0 = time.perf_counter(), time.process_time()
        inputs = load_inputs([str(rules)], graph_file=str(graph))
        plan = plan_episodes(inputs)[0]
        writer = recorder = None
        if run_dir is not None:
            writer = open_reasoning_run(run_dir, inputs, "tracelab bench reason-store", {"steps": STEPS})
            recorder = ReasoningRecorder(writer)
        episode = EpisodeRun(inputs, plan, trace=False, recorder=recorder)
        for _ in episode.steps(STEPS):
            pass
        episode.finish()
        t_closing = time.perf_counter()
        if writer is not None:
            writer.close()
        t1, cpu1 = time.perf_counter(), time.process_time()
    out.update(seconds=t1 - t0, cpu_s=cpu1 - cpu0, peak_rss_bytes=rss.peak,
               added_rss_bytes=rss.peak - out["base_rss_bytes"])
    if writer is not None:
        stats = writer.stats()
        out.update(change_rows=stats["rows"]["changes"], close_wait_s=t1 - t_closing,
                   changes_write_s=stats["seconds"]["changes"], rows=sum(stats["rows"].values()),
                   write_s=sum(stats["seconds"].values()), recorder_s=recorder.seconds,
                   run_bytes=sum(p.stat().st_size for p in run_dir.rglob("*") if p.is_file()))
    return out


def run(quick: bool, repeats: int, nodes: int | None = None) -> dict[str, Any]:
    nodes = nodes or (QUICK_NODES if quick else NODES)
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-reason-") as tmp:
        base = Path(tmp)
        rules = base / "spread.rules"
        rules.write_text(SPREAD_RULE)
        graph, small = base / f"g{nodes}.graphml", base / "small.graphml"
        facts = write_graph(graph, nodes)
        write_graph(small, 50)
        for run_dir in (None, base / "warm"):  # numba's caches, pyarrow and DuckDB load once per process
            reason_once(rules, small, run_dir)
        plain, recorded = [], []
        for i in range(max(1, repeats)):
            plain.append(reason_once(rules, graph, None))
            run_dir = base / f"run{i}"
            recorded.append(reason_once(rules, graph, run_dir))
            shutil.rmtree(run_dir)
        fresh = {mode: _child(rules, graph, base / "child" if mode == "run" else None) for mode in ("no_trace", "run")}
    med = lambda runs, key: summarize([r[key] for r in runs]).to_dict()  # noqa: E731
    result: dict[str, Any] = {
        "machine": machine_info(), "nodes": nodes, "edges": nodes * OUT_DEGREE, "facts": facts, "steps": STEPS,
        "repeats": max(1, repeats), "no_trace_s": med(plain, "seconds"), "run_s": med(recorded, "seconds"),
        "no_trace_cpu_s": med(plain, "cpu_s"), "run_cpu_s": med(recorded, "cpu_s"),
        "no_trace_added_rss_bytes": med(plain, "added_rss_bytes"),
        "run_added_rss_bytes": med(recorded, "added_rss_bytes"),
        "no_trace_fresh_peak_rss_bytes": fresh["no_trace"], "run_fresh_peak_rss_bytes": fresh["run"],
        "change_rows": recorded[0]["change_rows"], "rows": recorded[0]["rows"],
        "run_bytes": recorded[0]["run_bytes"],
        "changes_rows_per_s": summarize([r["change_rows"] / r["changes_write_s"] for r in recorded]).to_dict(),
        "all_rows_per_s": summarize([r["rows"] / r["write_s"] for r in recorded]).to_dict(),
        "recorder_s": med(recorded, "recorder_s"), "close_wait_s": med(recorded, "close_wait_s"),
        "writer_thread_s": med(recorded, "write_s"),
    }
    result["ratio"] = result["run_s"]["median"] / result["no_trace_s"]["median"]
    result["cpu_ratio"] = result["run_cpu_s"]["median"] / result["no_trace_cpu_s"]["median"]
    return result


def report(r: dict[str, Any]) -> str:
    m = lambda key: r[key]["median"]  # noqa: E731
    table = format_table(
        ["", "seconds", "CPU s (all threads)", "peak RSS MB (own process)", "RSS added MB (in turn)"],
        [["reason --no-trace", m("no_trace_s"), m("no_trace_cpu_s"), r["no_trace_fresh_peak_rss_bytes"] / 2**20,
          m("no_trace_added_rss_bytes") / 2**20],
         ["reason --run", m("run_s"), m("run_cpu_s"), r["run_fresh_peak_rss_bytes"] / 2**20,
          m("run_added_rss_bytes") / 2**20]])
    ratio_ok, rate_ok = r["ratio"] <= GOAL_RATIO, m("changes_rows_per_s") >= GOAL_ROWS_PER_S
    return (f"reason --run vs --no-trace: {SPREAD_RULE.strip()} on {r['nodes']:,} nodes / {r['edges']:,} edges "
            f"({r['facts']:,} facts), {r['steps']} steps; median of {r['repeats']} alternating runs in one process "
            f"(load average {r['machine']['load_average']})\n{table}\n"
            f"ratio {r['ratio']:.2f} (goal <= {GOAL_RATIO}: {'met' if ratio_ok else 'NOT met'}; CPU time "
            f"{r['cpu_ratio']:.2f}); "
            f"{r['change_rows']:,} change rows written at {m('changes_rows_per_s'):,.0f} rows/s by the writer's "
            f"thread (goal >= {GOAL_ROWS_PER_S:,}: {'met' if rate_ok else 'NOT met'}); every table "
            f"({r['rows']:,} rows) at {m('all_rows_per_s'):,.0f} rows/s, {m('writer_thread_s'):.2f} s of "
            f"writing in its thread; the reasoning spent {m('recorder_s'):.2f} s handing rows over and "
            f"{m('close_wait_s'):.2f} s waiting at close; the run takes {r['run_bytes'] / 2**20:.1f} MB")


def _child(rules: Path, graph: Path, run_dir: Path | None) -> int:
    """The peak resident memory of one reasoning in a fresh process, as `tracelab reason` has (the
    compiled code's load included)."""
    proc = subprocess.run([sys.executable, "-m", "tracelab.bench.reason_store", str(rules), str(graph),
                           str(run_dir or "")], capture_output=True, text=True, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"reason-store bench child failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return int(json.loads(proc.stdout.strip().splitlines()[-1])["peak_rss_bytes"])


if __name__ == "__main__":
    _rules, _graph, _run = sys.argv[1:4]
    reason_once(Path(_rules), Path(_graph), Path(_run) if _run else None)
    print(json.dumps({"peak_rss_bytes": high_water_bytes()}), flush=True)
