"""`tracelab show`: what a run is: its metadata, program, scenario and counts, read through the sandboxed
reader (tracelab.store.open_run)."""
from __future__ import annotations

import argparse
import json
from typing import Any

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._table import RULES_SHOWN
from tracelab.errors import store_errors
from tracelab.store.kind import spec_text, world_params
from tracelab.store.reader import open_run, retrying

DECLARED_FACTS = "declared_facts"  # a spec world's config entry (tracelab.envs.declared.recording.CONFIG_KEY)


def _json_field(text: str | None, default: Any) -> Any:
    try:
        return json.loads(text) if text else default
    except json.JSONDecodeError:
        return text


def describe_run(con: Any) -> dict[str, Any]:
    """The run's metadata, program, scenario (or a spec world's params) and counts as plain data."""
    rel = con.execute("SELECT * FROM run")
    names = [d[0] for d in rel.description]
    meta = dict(zip(names, rel.fetchall()[0]))
    for key, default in (("config", {}), ("rule_files", []), ("versions", {})):
        meta[key] = _json_field(meta.get(key), default)
    for key in ("started_at", "ended_at"):
        value = meta[key]
        meta[key] = value.isoformat(sep=" ", timespec="seconds") if hasattr(value, "isoformat") else value
    counts = dict(zip(
        ("changes", "steps", "metrics", "rules", "facts", "atoms", "groundings"),
        con.execute("SELECT (SELECT count(*) FROM raw.changes), (SELECT count(*) FROM raw.steps), "
                    "(SELECT count(*) FROM raw.metrics), (SELECT count(*) FROM raw.rules), "
                    "(SELECT count(*) FROM raw.facts), (SELECT count(*) FROM raw.atoms), "
                    "(SELECT count(*) FROM raw.groundings)").fetchall()[0]))
    outcomes = dict(con.execute("SELECT coalesce(outcome, 'not ended'), count(*) FROM episodes "
                                "GROUP BY 1 ORDER BY 2 DESC, 1").fetchall())
    rules = [dict(zip(("name", "text", "file", "line"), r)) for r in
             con.execute("SELECT name, text, file, line FROM rules ORDER BY rule").fetchall()]
    config = meta["config"] if isinstance(meta["config"], dict) else {}
    params = world_params(config, spec_text(con, config))
    scenario_text = config.get("scenario") if isinstance(config.get("scenario"), str) and params is None else None
    sources = [dict(zip(("role", "path", "bytes", "sha256", "text"), r)) for r in con.execute(
        "SELECT role, path, bytes, sha256, text FROM raw.sources").fetchall()] or sources_in_config(config)
    graph = dict(zip(("nodes", "edges"), con.execute(
        "SELECT (SELECT count(*) FROM raw.nodes), (SELECT count(*) FROM raw.edges)").fetchall()[0]))
    return {"run": meta, "episodes": {"total": sum(outcomes.values()), "by_outcome": outcomes},
            "counts": counts, "rules": rules, "params": params,
            "scenario": {"name": meta.get("scenario") if params is None else None, "definition": scenario_text},
            "board": meta.get("board"), "graph": graph, "sources": sources}


def sources_in_config(config: dict[str, Any]) -> list[dict[str, Any]]:
    """The program's files of a run written before the `sources` table: their texts were in meta.json's
    config (a spec world's `spec` and `rule_texts`)."""
    texts = config.get("rule_texts")
    rows = [{"role": "spec", "path": config.get("spec_path"), "text": config["spec"]}] \
        if isinstance(config.get("spec"), str) else []
    if isinstance(texts, dict):
        rows += [{"role": "rules", "path": path, "text": text} for path, text in texts.items() if isinstance(text, str)]
    return rows


# config entries shown in sections of their own (or as a spec world's params), not on the config line
OWN_SECTIONS = ("scenario", "sources", "translation", "graph", "spec", "rule_texts", "declared_board",
                 "declared_facts", "spec_path", "env_args", "env_id")


def render(doc: dict[str, Any], all_rules: bool = False) -> str:
    meta, counts = doc["run"], doc["counts"]
    lines = [f"run {meta['run_id']}: {meta['status']}",
             f"  command   {meta['command']}",
             f"  started   {meta['started_at']}   ended {meta['ended_at'] or '-'}",
             f"  seed      {meta['seed']}   host {meta['host']}   pid {meta['pid']}",
             "  versions  " + ", ".join(f"{k} {v}" for k, v in sorted(meta["versions"].items()))]
    config = meta["config"] if isinstance(meta["config"], dict) else {}
    # tracelab play --env: a world declared in rules (its spec's text in `sources`, in an older run the config)
    spec = next((s for s in doc["sources"] if s["role"] == "spec"), None)
    declared = spec is not None or DECLARED_FACTS in config
    lines.append(f"  board     {doc['board']}" if doc["board"] else
                 ("  board     the spec's [board] (drawn by the TUI and the replay)" if config.get("declared_board")
                  else "  board     none: a spec world without a [board]") if declared
                 else "  board     none: a reasoning run (its episodes are reasonings, not games)")
    for f in meta["rule_files"]:
        lines.append(f"  rules     {f.get('path')} (sha256 {str(f.get('sha256'))[:12]})")
    for source in config.get("sources") or []:
        if isinstance(source, dict) and source.get("role") in ("graph", "facts-table"):
            size = f" ({source['bytes']:,} bytes)" if isinstance(source.get("bytes"), int) else ""
            lines.append(f"  {source['role']:<9} {source.get('path')}{size}")
    shown = {k: v for k, v in config.items() if k not in OWN_SECTIONS} \
        if isinstance(meta["config"], dict) else meta["config"]
    if shown:
        lines.append(f"  config    {json.dumps(shown, sort_keys=True)}")
    if doc["params"] is not None:  # a spec world's: its [params] with the run's keyword arguments over them
        lines.append("  params    " + (", ".join(f"{k} = {json.dumps(v)}" for k, v in doc["params"].items())
                                       or "none (the spec declares no [params])"))
    episodes = doc["episodes"]
    lines += ["", f"episodes  {episodes['total']}" + (
        " (" + ", ".join(f"{n} {o}" for o, n in episodes["by_outcome"].items()) + ")" if episodes["total"] else "")]
    lines.append("rows      " + ", ".join(f"{n:,} {name}" for name, n in counts.items()))
    if doc["graph"]["edges"]:
        lines.append(f"graph     {doc['graph']['nodes']:,} nodes, {doc['graph']['edges']:,} edges")
    scenario = doc["scenario"]
    if scenario["name"] or scenario["definition"]:
        lines += ["", f"scenario  {scenario['name']}"]
    if scenario["definition"]:
        lines += ["  " + ln for ln in scenario["definition"].rstrip().splitlines()]
    if declared:
        env = config.get("env")
        lines += ["", f"spec      {config.get('spec_path') or (env.get('name') if isinstance(env, dict) else env)}"]
        lines += ["  " + ln for ln in (spec and spec["text"] or "").rstrip().splitlines()]
    rules = doc["rules"]
    shown = rules if all_rules else rules[:RULES_SHOWN]
    lines += ["", f"program   {len(rules)} rules, {counts['facts']} facts"]
    lines += [f"  {' '.join(r['text'].split())}" for r in shown]
    if len(shown) < len(rules):
        lines.append(f"  ... {len(rules) - len(shown)} more (--all-rules, or "
                     "tracelab sql RUN \"SELECT * FROM rules\")")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    with store_errors(), ctrl_c_stops_queries():
        con = open_run(args.run)
        doc = retrying(lambda: describe_run(con))
    print(json.dumps(doc, indent=1, default=str) if args.json else render(doc, args.all_rules))
    return 0
