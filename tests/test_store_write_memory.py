"""What a process that writes a run loads (issue 31 part 3, docs/benchmarks/history.md "Memory of long runs"):
`tracelab play --run`'s writing path, merges of small parts included, imports neither DuckDB (~10 MB
resident plus its catalog), nor pandas (~30 MB: pyarrow's converter imports it on first use), nor Arrow's
dataset layer (pq.read_table's: ~15 MB), nor pyarrow.compute (~7 MB; a game's graph has no facts). And
the arrays built without pyarrow's converter (tracelab.store.arrow_build) are the converter's, value for
value."""
from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pytest

from tracelab.store import arrow_build as ab
from tracelab.store.schema import SCHEMAS

DEFERRED = ("duckdb", "pandas", "pyarrow.dataset", "pyarrow.compute")

PLAY_INTO_A_RUN = """
import json, sys
from pathlib import Path
from tracelab.envs.declared.env_source import EnvSource
from tracelab.envs.declared.play import load_declared, make_declared_env, play_episodes, random_policy
from tracelab.store import TraceWriter

writer = TraceWriter.open(Path(sys.argv[1]), {"command": "test"}, compact_files=2)  # merges early
source = EnvSource.given("tracelab/GridWar-advanced-v0", {})
env = make_declared_env(source, load_declared(source), trace_writer=writer)
act = random_policy(env, 3)

def flushed(obs, info):
    writer.flush()  # a part per step: small parts, merged in twos
    return act(obs, info)

play_episodes(env, 12, 3, flushed)
env.close()
writer.close()
print(json.dumps({"loaded": [m for m in sys.argv[2:] if m in sys.modules],
                  "compactions": writer.stats()["compactions"]}))
"""


def test_playing_into_a_run_loads_no_duckdb_pandas_or_arrow_datasets(tmp_path) -> None:
    proc = subprocess.run([sys.executable, "-c", PLAY_INTO_A_RUN, str(tmp_path / "run"), *DEFERRED],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["compactions"] > 0  # the merge path ran
    assert out["loaded"] == []
    # and the run reads back (DuckDB loaded by the reader, here)
    from tracelab.store import open_run
    con = open_run(tmp_path / "run")
    try:
        assert con.execute("SELECT count(*) FROM episodes WHERE ended").fetchone()[0] == 12
    finally:
        con.close()


def test_the_store_package_imports_its_reader_only_when_asked() -> None:
    code = ("import sys, tracelab.store as s; before = 'duckdb' in sys.modules; s.open_run; "
            "print(before, 'duckdb' in sys.modules, s.TraceWriter.__name__, 'open_run' in dir(s))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.stdout.split() == ["False", "True", "TraceWriter", "True"], proc.stderr[-2000:]


def _value(t: pa.DataType, rng: np.random.Generator):
    if rng.random() < 0.2:
        return None
    if pa.types.is_string(t):
        return rng.choice(["", "a", "ä-ü", "red-agent-1", "x" * 40])
    if pa.types.is_boolean(t):
        return bool(rng.integers(2))
    if pa.types.is_integer(t):
        info = np.iinfo(t.to_pandas_dtype())
        return int(rng.choice([info.min, info.max, 0, -1, int(rng.integers(-100, 100))]))
    if pa.types.is_floating(t):
        return float(rng.choice([0.0, -0.0, 1.5, float("nan"), float("inf"), rng.normal()]))
    if pa.types.is_timestamp(t):
        return dt.datetime(2026, 11, 25, 6, 30) + dt.timedelta(microseconds=int(rng.integers(-10**12, 10**12)))
    if pa.types.is_list(t):
        return [v for v in (_value(t.value_type, rng) for _ in range(int(rng.integers(0, 4)))) if v is not None]
    raise AssertionError(t)


@pytest.mark.parametrize("table", sorted(SCHEMAS))
def test_tables_from_rows_are_pyarrows(table: str) -> None:
    schema = SCHEMAS[table]
    rng = np.random.default_rng(len(table))
    for n in (0, 1, 9, 200):
        rows = [{f.name: _value(f.type, rng) for f in schema if rng.random() < 0.95} for _ in range(n)]
        for row in rows:  # a NULL list is not something the writer makes
            for f in schema:
                if pa.types.is_list(f.type) and row.get(f.name) is None:
                    row[f.name] = []
        built, expected = ab.table_from_rows(rows, schema), pa.Table.from_pylist(rows, schema=schema)
        built.validate(full=True)
        assert built.schema == expected.schema
        assert repr(built.to_pylist()) == repr(expected.to_pylist()), table  # repr: NaN as 'nan'


@pytest.mark.parametrize("dtype", ["int8", "int16", "int32", "int64", "float32", "float64", "bool"])
def test_numpy_arrays_are_pyarrows(dtype: str) -> None:
    rng = np.random.default_rng(1)
    values = (rng.normal(size=300) * 100).astype(dtype)
    for part in (values, values[3:], values[::2], values[:0]):
        assert ab.from_numpy(part).equals(pa.array(part))
    null = rng.random(300) < 0.3
    assert ab.from_numpy(values, null=null).equals(pa.array(values, mask=null))
    if dtype == "bool":
        sliced = ab.from_numpy(values).slice(5)
        assert (ab.bools_to_numpy(sliced) == values[5:]).all()
    with pytest.raises(TypeError):
        ab.from_numpy(values, pa.int16() if dtype != "int16" else pa.int32())


def test_strings_scalars_lists_and_empty_tables_are_pyarrows() -> None:
    texts = ["", "é", None, "atLoc(red-agent-1,56)", None]
    assert ab.strings(texts).equals(pa.array(texts, pa.string()))
    assert ab.scalar("(").equals(pa.scalar("(", pa.string()))
    offsets = np.array([0, 2, 2, 5])
    values = np.arange(5, dtype=np.int32)
    assert ab.list_array(offsets, ab.from_numpy(values)).equals(
        pa.ListArray.from_arrays(pa.array(offsets.astype(np.int32)), pa.array(values)))
    for schema in SCHEMAS.values():
        assert ab.empty_table(schema).equals(schema.empty_table())


def test_back_pressure_flushes_at_max_pending_rows_without_waiting_for_the_interval(tmp_path) -> None:
    # the buffers are capped at max_pending_rows: reaching it makes a flush due at once (a caller held at
    # the cap once waited for flush_interval when the cap was below part_rows)
    import threading

    from tracelab.store import TraceWriter

    writer = TraceWriter.open(tmp_path / "run", {"command": "test"}, max_pending_rows=1_000, part_rows=10**6,
                              flush_interval=120.0)

    def write() -> None:
        for k in range(30):
            writer.write_steps(np.int64(0), {"step": np.arange(100 * k, 100 * k + 100), "action": np.zeros(100),
                                             "reward": np.zeros(100)})

    thread = threading.Thread(target=write, daemon=True)
    thread.start()
    thread.join(timeout=30)
    alive = thread.is_alive()
    writer.close()
    assert not alive, "a caller at max_pending_rows waited for flush_interval"
    assert writer.stats()["rows"]["steps"] == 3_000


def test_coded_strings_and_lists_with_nulls_are_the_converters() -> None:
    names = ["up", "down", "ä-left", "", "shoot"]
    codes = np.random.default_rng(0).integers(0, len(names), 1000)
    assert ab.coded_strings(codes, names).equals(pa.array([names[c] for c in codes]))
    assert ab.coded_strings(np.array([], np.int64), names).equals(pa.array([], pa.string()))
    rows = [["a", "b"], None, [], ["c"]]
    built = ab.list_array(np.array([0, 2, 2, 2, 3]), ab.strings(["a", "b", "c"]),
                          null=np.array([r is None for r in rows]))
    assert built.equals(pa.array(rows, pa.list_(pa.string())))
