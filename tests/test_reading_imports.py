"""A reading command loads only what it uses (issue 40): printing a table, DuckDB alone (its rows print without
pyarrow: commands._output.write_rows); the why searches (why, why-not, and of an agent's action) DuckDB alone
too, without the engine's parser (an atom written as the store writes it is read without it, nor the program's
types: store.model.RunModel.parse_atom; a small episode's rows are Python lists: store.episode.PYTHON_ROWS; an
agent's decision is read by why/why-not --action only); streaming CSV/JSON/Parquet and diffing also pyarrow
and numpy (which pyarrow imports); never pandas (pyarrow's converter imports it for a Python list:
tracelab.store.arrow_build builds from buffers), numba, torch, rerun, textual or the rest. Each command runs
in one child interpreter, in turn (the DuckDB-only ones first, so that what they leave in sys.modules is
theirs alone), and the heavy packages loaded so far are printed after each: one that loads a forbidden package
is named. A command builds its own parser only: no other command's module is imported. Nor does a reading
command load `logging` (no notice is printed: tracelab.engine.notices imports it when a module first logs),
the board's module, or meta.json's (a sealed run's readers never read it); `why --action` loads none of
the world's why search; and the why searches' modules define no dataclass (~1-2 ms of CPU each to make)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tracelab.cli import command_module

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "sample_runs"
PLAY = str(RUNS / "advanced")
TRAIN = str(RUNS / "base-train")

ALLOWED = {"duckdb", "pyarrow", "numpy", "logging"}   # pyarrow imports logging
DUCKDB_ONLY = {"duckdb"}
# Modules a few commands load, allowed from the first command that does on (they share one process): the
# agent's decision (why/why-not --action), the world's why search (why of an atom, why-not of a rule),
# meta.json's reader (runs and check read a run's metadata file).
LOADED_BY = {
    "tracelab.store.agent_why": lambda argv: "--action" in argv,
    "tracelab.store.why": lambda argv: argv[0] in ("why", "why-not") and "--action" not in argv,
    "tracelab.store.meta": lambda argv: argv[0] in ("runs", "check"),
}
HEAVY = ("torch", "ray", "pandas", "pyarrow", "numpy", "tracelab.engine.parser", "duckdb", "rerun", "textual",
         "matplotlib", "numba", "llvmlite", "scipy", "stable_baselines3", "tensorboard", "gymnasium", "pettingzoo",
         "networkx",
         # lighter, still not used: the program's types (the why searches read atoms and test bounds with
         # engine.spelling and engine.bounds), a did-you-mean's difflib (a mistyped name only)
         "tracelab.engine.program", "difflib", "logging", "tracelab.board", *LOADED_BY)

# These print tables from DuckDB's rows, or answer why from them: DuckDB is all they load.
DUCKDB_COMMANDS = [
    ["sql", PLAY, "SELECT label, count(*) FROM atoms GROUP BY ALL ORDER BY ALL LIMIT 3"],
    ["sql", str(RUNS / "base"), str(RUNS / "nonmarkov"), "SELECT run, count(*) FROM changes GROUP BY ALL"],
    ["sql", "--query", "rule_coverage", PLAY],
    ["trace", PLAY, "--episode", "0", "--from", "1", "--to", "4"],
    ["show", PLAY],
    ["show", TRAIN],
    ["runs", str(RUNS)],
    ["check", PLAY],
    ["why", TRAIN, "--action", "red-agent-1", "--episode", "776", "--at", "2"],
    ["why-not", TRAIN, "--action", "up", "--episode", "776", "--at", "2"],
    ["why", PLAY, "captured(blue)", "--episode", "0", "--at", "21", "--depth", "3"],
    ["why", PLAY, "captured(blue)", "--episode", "0", "--at", "21", "--depth", "3", "--json"],
    ["why-not", PLAY, "--rule", "snap_at", "--episode", "0", "--at", "21"],
    ["compare", TRAIN],   # the reward scale's text without the trainer's config (numpy): train/reward_scale.py
]
COMMANDS = [
    *DUCKDB_COMMANDS,
    ["sql", "--format", "csv", PLAY, "SELECT * FROM changes LIMIT 3"],
    ["sql", "--format", "json", str(RUNS / "base"), str(RUNS / "nonmarkov"),
     "SELECT run, count(*) FROM changes GROUP BY ALL"],
    ["sql", "--query", "rule_coverage", str(RUNS / "base"), str(RUNS / "nonmarkov")],
    ["trace", PLAY, "--episode", "0", "--from", "1", "--to", "4", "--format", "csv"],
    ["diff", PLAY, "0", "1"],
    ["runs", "--format", "json", str(RUNS)],
    ["compare", "--format", "json", TRAIN],
]

CHILD = """
import contextlib, io, json, sys
from tracelab.cli import main
def commands_loaded():
    return [m for m in sys.modules if m.startswith("tracelab.commands.") and not m.rpartition(".")[2].startswith("_")]
heavy, commands = json.loads(sys.argv[1]), json.loads(sys.argv[2])
for argv in commands:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = main(argv)
    print(json.dumps({"argv": argv, "status": status, "printed": bool(out.getvalue()),
                      "loaded": [m for m in heavy if m in sys.modules],
                      "commands": commands_loaded()}), file=sys.__stdout__)
"""


def test_reading_commands_load_only_duckdb_and_for_arrow_output_pyarrow_and_numpy() -> None:
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(HEAVY), json.dumps(COMMANDS)], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    reports = [json.loads(line) for line in out.stdout.splitlines()]
    assert [r["argv"] for r in reports] == COMMANDS, out.stderr
    for r in reports:
        assert r["status"] == 0 and r["printed"], (r, out.stderr)  # each command did its work
        allowed = DUCKDB_ONLY if r["argv"] in DUCKDB_COMMANDS else ALLOWED
        allowed = allowed | {m for m, loads in LOADED_BY.items() if any(map(loads, COMMANDS[:reports.index(r) + 1]))}
        assert set(r["loaded"]) <= allowed, f"{' '.join(r['argv'][:1])} loaded {sorted(set(r['loaded']) - allowed)}"
        ran = {command_module(argv[0]) for argv in COMMANDS[:reports.index(r) + 1]}
        assert set(r["commands"]) <= ran, f"{r['argv'][0]} imported {sorted(set(r['commands']) - ran)}"
    assert {"duckdb", "pyarrow"} <= set(reports[-1]["loaded"])  # the check sees what a command loads


def test_the_why_searches_define_no_dataclass() -> None:
    """Their records are NamedTuples and plain classes: each dataclass costs ~1-2 ms of CPU to make at import,
    a good part of what `why` adds to DuckDB's own start-up."""
    import dataclasses
    import importlib
    modules = ["tracelab.store.reader", "tracelab.store.kind", "tracelab.store.coordinates", "tracelab.store.model",
               "tracelab.store.episode", "tracelab.store.why", "tracelab.store.agent_why", "tracelab.store.sandbox",
               "tracelab.store.sealed_catalog", "tracelab.store.checked_files", "tracelab.engine.duckdb_limits"]
    found = [f"{name}.{value.__name__}" for name in modules for value in vars(importlib.import_module(name)).values()
             if isinstance(value, type) and value.__module__ == name and dataclasses.is_dataclass(value)]
    assert found == []


GC_CHILD = """
import contextlib, gc, io, json, sys
from tracelab.cli import main
during = []   # a collection while the command's module was being imported (in sys.modules, `run` not yet made)
def seen(phase, info):
    m = sys.modules.get("tracelab.commands.why")
    if phase == "start" and m is not None and not hasattr(m, "run"):
        during.append(info["generation"])
gc.callbacks.append(seen)
argv, own_line = json.loads(sys.argv[1]), sys.argv[2] == "command line"
if own_line:
    sys.argv = ["tracelab", *argv]
with contextlib.redirect_stdout(io.StringIO()):
    status = main() if own_line else main(argv)
print(json.dumps({"status": status, "during": during, "enabled": gc.isenabled(), "frozen": gc.get_freeze_count()}))
"""


def test_no_garbage_collection_while_a_command_starts() -> None:
    """Importing the command's module (DuckDB's ~20,000 objects) runs no collection (~30 of them cost ~15 ms
    of CPU of `why --action`), and its objects stay frozen (no collection traverses them, the one at exit
    included) in a process that runs its command line; a command run in its caller's process (argv given)
    leaves the collector on, with nothing frozen, as it found it."""
    argv = ["why", TRAIN, "--action", "red-agent-1", "--episode", "776", "--at", "2"]
    reports = {}
    for how in ("command line", "in a caller's process"):
        out = subprocess.run([sys.executable, "-c", GC_CHILD, json.dumps(argv), how], cwd=ROOT,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        reports[how] = json.loads(out.stdout.splitlines()[-1])
    frozen = reports["command line"].pop("frozen")
    assert frozen > 10_000 and reports["command line"] == {"status": 0, "during": [], "enabled": True}
    assert reports["in a caller's process"] == {"status": 0, "during": [], "enabled": True, "frozen": 0}
