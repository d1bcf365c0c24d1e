"""Turn the engine's columnar output (trace dicts, vocabulary, grounding table, program) and the RL loop's
data (steps, metrics) into Arrow tables with the store's schemas, checking them on the way in.

Numeric columns are handed to Arrow without copies where the dtype already matches."""
from __future__ import annotations

import datetime as _dt
import functools
import json
from collections.abc import Callable, Collection, Mapping, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from tracelab.engine.program import INCONSISTENCY_POLICIES
from tracelab.store import arrow_build as ab
from tracelab.store.graph_tables import graph_fact_table
from tracelab.store.schema import SCHEMAS, TRACE_COLUMNS


def _col(arrays: Mapping[str, Any], name: str, dtype: str, n: int | None, what: str,
         copy: bool = True) -> np.ndarray:
    if name not in arrays:
        raise KeyError(f"{what} has no column {name!r} (columns: {sorted(arrays)})")
    a = np.asarray(arrays[name])
    if a.ndim != 1:
        raise ValueError(f"{what} column {name!r} must be 1-D, got shape {a.shape}")
    if n is not None and len(a) != n:
        raise ValueError(f"{what} column {name!r} has {len(a)} rows, expected {n}")
    if a.dtype.kind == "f" and np.dtype(dtype).kind == "i":
        raise TypeError(f"{what} column {name!r} is {a.dtype}; expected integers ({dtype})")
    # A copy unless the caller hands the arrays over: the rows wait in a buffer until the flusher writes
    # them, and a caller (an RL loop's arrays) may reuse its memory meanwhile.
    return np.array(a, dtype=dtype) if copy else np.asarray(a, dtype=dtype)


def _list_array(offsets: np.ndarray, values: np.ndarray, value_type: pa.DataType) -> pa.ListArray:
    return ab.list_array(offsets, ab.from_numpy(values, value_type))


def trace_table(arrays: Mapping[str, Any], episode: int | Sequence[int] | np.ndarray | None,
                seq_start: int, n_atoms: int, n_groundings: int, owned: bool = False) -> pa.Table:
    """Trace rows (the dict `Engine.take_trace()` returns) as raw.changes rows numbered from seq_start.

    episode: one id for every row; or a sequence indexed by world (the episode each world is playing);
    or None when `arrays` carries an `episode` column of its own. owned: the caller hands the arrays over
    (as take_trace's, which the engine never touches again): they are not copied."""
    if "pass_no" not in arrays and "pass" in arrays:
        arrays = {**arrays, "pass_no": arrays["pass"]}
    cols = {name: _col(arrays, name, dtype, None, "trace", copy=not owned)
            for name, dtype in TRACE_COLUMNS.items()}
    lengths = {name: len(a) for name, a in cols.items()}
    n = lengths["t"]
    if len(set(lengths.values())) > 1:
        raise ValueError(f"trace columns differ in length: {lengths}")
    if "episode" in arrays:
        ep = _col(arrays, "episode", "int64", n, "trace")
    elif episode is None:
        raise ValueError("trace rows need an episode: pass episode= or an 'episode' column")
    elif np.ndim(episode) == 0:
        ep = np.full(n, int(episode), dtype=np.int64)
    else:
        by_world = np.asarray(episode, dtype=np.int64)
        w = cols["world"]
        if n and (w.min() < 0 or w.max() >= len(by_world)):
            bad = int(w.max() if w.max() >= len(by_world) else w.min())
            raise ValueError(f"trace row has world {bad} but the episode-by-world array has "
                             f"{len(by_world)} entries")
        ep = by_world[w]
    if n:
        a = cols["atom"]
        if a.min() < 0 or a.max() >= n_atoms:
            bad = int(a.max() if a.max() >= n_atoms else a.min())
            raise ValueError(f"trace row refers to atom id {bad}, but the store has {n_atoms} atoms; "
                             "write the vocabulary (write_vocabulary) before the rows that use it")
        g = cols["grounding"]
        if g.min() < -1 or g.max() >= n_groundings:
            bad = int(g.max() if g.max() >= n_groundings else g.min())
            raise ValueError(f"trace row refers to grounding id {bad}, but the store has {n_groundings} "
                             "groundings; write the grounding table before the rows that use it")
        k = cols["cause_kind"]
        if k.min() < 0 or k.max() > 4:
            bad = int(k.max() if k.max() > 4 else k.min())
            raise ValueError(f"trace row has cause_kind {bad}; known kinds are 0..4")
    seq = np.arange(seq_start, seq_start + n, dtype=np.int64)
    data = {"seq": seq, "episode": ep, **cols}
    return ab.table({name: ab.from_numpy(a) for name, a in data.items()}, SCHEMAS["changes"])


# ---- vocabulary and groundings: suffixes beyond what is already stored -------------------------------

def vocabulary_tables(vocab: Mapping[str, Any], have: Mapping[str, int]) -> dict[str, pa.Table]:
    """The nodes, labels and atoms of `vocab` (Engine.vocabulary()) past the counts in `have`."""
    nodes = list(vocab["nodes"])
    labels = list(vocab["labels"])
    arity = np.asarray(vocab["label_arity"], dtype=np.int8)
    atom_label = np.asarray(vocab["atom_label"], dtype=np.int32)
    arg0 = np.asarray(vocab["atom_arg0"], dtype=np.int32)
    arg1 = np.asarray(vocab["atom_arg1"], dtype=np.int32)
    if len(arity) != len(labels):
        raise ValueError(f"vocabulary has {len(labels)} labels but {len(arity)} label arities")
    if not len(atom_label) == len(arg0) == len(arg1):
        raise ValueError(f"vocabulary atom arrays differ in length: atom_label {len(atom_label)}, "
                         f"atom_arg0 {len(arg0)}, atom_arg1 {len(arg1)}")
    for name, now in (("nodes", len(nodes)), ("labels", len(labels)), ("atoms", len(atom_label))):
        if now < have[name]:
            raise ValueError(f"vocabulary shrank: it has {now} {name}, the store already holds {have[name]}")
    n0, l0, a0 = have["nodes"], have["labels"], have["atoms"]
    out = {
        "nodes": ab.table({"node": ab.from_numpy(np.arange(n0, len(nodes), dtype=np.int32)),
                           "name": ab.strings([str(x) for x in nodes[n0:]])}, SCHEMAS["nodes"]),
        "labels": ab.table({"label": ab.from_numpy(np.arange(l0, len(labels), dtype=np.int32)),
                            "name": ab.strings([str(x) for x in labels[l0:]]),
                            "arity": ab.from_numpy(arity[l0:])}, SCHEMAS["labels"]),
        "atoms": ab.table({"atom": ab.from_numpy(np.arange(a0, len(atom_label), dtype=np.int32)),
                           "label": ab.from_numpy(atom_label[a0:]), "arg0": ab.from_numpy(arg0[a0:]),
                           "arg1": ab.from_numpy(arg1[a0:])}, SCHEMAS["atoms"]),
    }
    sl = atom_label[a0:]
    if len(sl) and (sl.min() < 0 or sl.max() >= len(labels)):
        raise ValueError(f"vocabulary atom has label id {int(sl.max())} but there are {len(labels)} labels")
    for name, args in (("atom_arg0", arg0[a0:]), ("atom_arg1", arg1[a0:])):
        if len(args) and args.max() >= len(nodes):
            raise ValueError(f"vocabulary {name} has node id {int(args.max())} but there are "
                             f"{len(nodes)} nodes")
    return out


def _field(obj: Any, name: str) -> np.ndarray:
    value = obj[name] if isinstance(obj, Mapping) else getattr(obj, name)
    return np.asarray(value)


def grounding_count(groundings: Any) -> int:
    return len(_field(groundings, "rule"))


def groundings_table(groundings: Any, have: int) -> pa.Table:
    """Groundings past id `have` from an engine GroundingTable (or a dict with its five arrays)."""
    rule = _field(groundings, "rule").astype(np.int32, copy=False)
    body_ptr = _field(groundings, "body_ptr").astype(np.int64, copy=False)
    body = _field(groundings, "body_atoms").astype(np.int32, copy=False)
    var_ptr = _field(groundings, "var_ptr").astype(np.int64, copy=False)
    var = _field(groundings, "var_values").astype(np.int32, copy=False)
    g = len(rule)
    if len(body_ptr) != g + 1 or len(var_ptr) != g + 1:
        raise ValueError(f"grounding table has {g} groundings but body_ptr has {len(body_ptr)} and "
                         f"var_ptr {len(var_ptr)} entries (expected {g + 1})")
    if g < have:
        raise ValueError(f"grounding table shrank: it has {g} groundings, the store already holds {have}")
    bp = body_ptr[have:] - body_ptr[have]
    vp = var_ptr[have:] - var_ptr[have]
    return pa.Table.from_arrays([
        ab.from_numpy(np.arange(have, g, dtype=np.int32)), ab.from_numpy(rule[have:]),
        _list_array(bp, body[body_ptr[have]:body_ptr[g]], pa.int32()),
        _list_array(vp, var[var_ptr[have]:var_ptr[g]], pa.int32()),
    ], schema=SCHEMAS["groundings"])


# ---- the program ---------------------------------------------------------------------------------------

def _clause_row(rule_id: int, pos: int, lit: Any, closed: Collection[str]) -> dict[str, Any]:
    return {"rule": rule_id, "pos": pos, "label": lit.pred, "args": [t.name for t in lit.args],
            "is_var": [bool(t.is_var) for t in lit.args], "negated": bool(lit.negated),
            "lower": float(lit.lower), "upper": float(lit.upper), "text": str(lit),
            "closed": lit.pred in closed}


def program_tables(program: Any, facts: Sequence[Any] | None = None, graph: Any = None,
                   file_name: Callable[[str], str] | None = None) -> dict[str, pa.Table]:
    """raw.rules, raw.clauses, raw.facts and raw.policies of a parsed Program (tracelab.engine.program).
    facts: the fact list the trace's fact ids index (Engine.facts: graph facts, then the program's);
    defaults to program.facts. graph: a Graph whose facts come first (Engine.facts' order), written as
    columns (tracelab.store.graph_tables); then `facts` are the program's and are numbered after them.
    file_name: how a rule's or fact's file is recorded (the writer's portable paths), asked once a file."""
    recorded = functools.cache(file_name) if file_name is not None else None

    def _loc(item: Any) -> tuple[str | None, int | None]:
        loc = getattr(item, "loc", None)
        if not loc:
            return None, None
        return (recorded(loc.file) if recorded is not None and loc.file is not None else loc.file), loc.line

    rules, clauses, fact_rows = [], [], []
    for i, r in enumerate(program.rules):
        file, line = _loc(r)
        rules.append({"rule": i, "name": r.name, "text": r.text or "", "head": str(r.head),
                      "delay": int(r.delay), "immediate": bool(r.immediate),
                      "mode": r.mode or program.mode, "variables": list(r.variables),
                      "file": file, "line": line})
        clauses.append(_clause_row(i, -1, r.head, program.closed))
        clauses.extend(_clause_row(i, k, lit, program.closed) for k, lit in enumerate(r.body))
    first = graph.n_facts if graph is not None else 0
    for i, f in enumerate(program.facts if facts is None else facts, start=first):
        file, line = _loc(f)
        fact_rows.append({"fact": i, "name": f.name, "text": f.text or "", "literal": str(f.literal),
                          "start": int(f.start), "end": int(f.end), "static": bool(f.static),
                          "file": file, "line": line})
    policies = [{"code": i, "name": p} for i, p in enumerate(INCONSISTENCY_POLICIES)]
    return {
        "rules": ab.table_from_rows(rules, SCHEMAS["rules"]),
        "clauses": ab.table_from_rows(clauses, SCHEMAS["clauses"]),
        "facts": pa.concat_tables([*([graph_fact_table(graph, recorded)] if graph is not None else []),
                                   ab.table_from_rows(fact_rows, SCHEMAS["facts"])]),
        "policies": ab.table_from_rows(policies, SCHEMAS["policies"]),
    }


# ---- episodes, steps, metrics ----------------------------------------------------------------------------

def utc_now() -> _dt.datetime:
    """Now, in UTC, without tzinfo (the store's timestamps are all UTC)."""
    return _dt.datetime.now(_dt.UTC).replace(tzinfo=None)


def json_text(value: Any) -> str | None:
    return None if value is None else json.dumps(value, sort_keys=True, default=str)


def steps_table(episode: int | np.ndarray, arrays: Mapping[str, Any]) -> pa.Table:
    """Per-step rows: `step`, `action`, `reward` (arrays of one length, or scalars) and optionally
    `agent` (str or array of str), `t`, `terminated`, `truncated`, `obs` (2-D: one row per step row).
    `episode`: the rows' episode, or an array with each row's."""
    for req in ("step", "action", "reward"):
        if req not in arrays:
            raise KeyError(f"steps need a {req!r} column (got {sorted(arrays)})")
    unknown = set(arrays) - {"step", "action", "reward", "agent", "t", "terminated", "truncated", "obs"}
    if unknown:
        raise KeyError(f"unknown step column(s) {sorted(unknown)}")
    n = max((np.size(arrays[k]) for k in arrays if k not in ("obs",) and np.ndim(arrays[k]) > 0),
            default=1)

    def col(name: str, dtype: Any, default: Any) -> np.ndarray:
        v = np.asarray(arrays.get(name, default))
        if v.ndim == 0:
            return np.full(n, v.item() if v.dtype.kind != "U" else str(v), dtype=dtype)
        if len(v) != n:
            raise ValueError(f"step column {name!r} has {len(v)} rows, expected {n}")
        return v.astype(dtype)  # a copy: the caller may reuse its buffers

    if "obs" in arrays and arrays["obs"] is not None:
        obs = np.array(arrays["obs"], dtype=np.float32)  # a copy, as above
        if obs.ndim == 1 and n == 1:
            obs = obs[None, :]
        if obs.ndim != 2 or obs.shape[0] != n:
            raise ValueError(f"step column 'obs' must be 2-D with {n} rows, got shape {obs.shape}")
        d = obs.shape[1]
        obs_arr = _list_array(np.arange(0, (n + 1) * d, d, dtype=np.int64)[: n + 1],
                              obs.reshape(-1), pa.float32())
    else:
        obs_arr = pa.nulls(n, type=pa.list_(pa.float32()))
    agent = np.asarray(arrays.get("agent", ""))
    agents = [str(agent)] * n if agent.ndim == 0 else agent.astype(str).tolist()  # 3x a str() per row
    if len(agents) != n:
        raise ValueError(f"step column 'agent' has {len(agents)} rows, expected {n}")
    episodes = np.asarray(episode, dtype=np.int64)
    if episodes.ndim and len(episodes) != n:
        raise ValueError(f"steps' episode array has {len(episodes)} rows, expected {n}")
    return pa.Table.from_arrays([
        ab.from_numpy(np.full(n, episodes) if episodes.ndim == 0 else episodes),
        ab.from_numpy(col("step", np.int32, 0)), ab.from_numpy(col("t", np.int32, -1)), ab.strings(agents),
        ab.from_numpy(col("action", np.int32, 0)), ab.from_numpy(col("reward", np.float64, 0.0)),
        ab.from_numpy(col("terminated", np.bool_, False)), ab.from_numpy(col("truncated", np.bool_, False)),
        obs_arr,
    ], schema=SCHEMAS["steps"])


def metrics_table(step: int, values: Mapping[str, float], episode: int | None) -> pa.Table:
    names = list(values)
    vals = []
    for k in names:
        try:
            vals.append(float(values[k]))
        except (TypeError, ValueError):
            raise TypeError(f"metric {k!r} has non-numeric value {values[k]!r}") from None
    now = utc_now()
    return ab.table_from_rows([{"step": int(step), "name": name, "value": value, "episode": episode,
                                "time": now} for name, value in zip(names, vals)], SCHEMAS["metrics"])
