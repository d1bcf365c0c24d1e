"""`tracelab bench store`: the trace store's own benchmark (tracelab.store.bench.store_benchmark), with
the machine record and a table."""
from __future__ import annotations

from typing import Any

from tracelab.bench.common import format_table, machine_info, summarize
from tracelab.bench.engine import machine_line
from tracelab.store.bench import store_benchmark


def run(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    """Ingest rows/s (median over `repeats` runs), seal rows/s and point-query latency; --quick ingests
    200k rows instead of 2M."""
    info = machine_info()
    result = store_benchmark(rows=200_000 if quick else 2_000_000, repeats=max(1, repeats))
    info["load_average_end"] = machine_info()["load_average"]
    return {"machine": info, "quick": quick, "repeats": repeats, "store": result,
            "ingest_rows_per_s": summarize(result["ingest_rows_per_s_runs"]).to_dict()}


def report(r: dict[str, Any]) -> str:
    s, ingest = r["store"], r["ingest_rows_per_s"]
    table = format_table(["trace store", "value", "spread"], [
        ["rows ingested per run", s["rows"], ""],
        ["ingest rows/s (TraceWriter, to published Parquet)", ingest["median"],
         f"{100 * ingest['spread']:.0f}%"],
        ["seal rows/s", s["seal_rows_per_s"], ""],
        ["point query ms, live", s["point_query_ms_live"], ""],
        ["point query ms, sealed", s["point_query_ms_sealed"], ""],
    ])
    return machine_line(r["machine"], r["quick"], r["repeats"]) + "\n\n" + table
