"""Run PyReason's own example scripts unchanged with `python -m tracelab.pyreason` and print the table of
docs/pyreason.md ("PyReason's examples, run unchanged"): per script whether it ran (the last line of its
error when it did not) and how its output compares with what PyReason states of it: the rule trace it
saves against the one PyReason's repository commits for it (examples/csv_outputs), row by row and column
by column, or its own asserts.

    python examples/pyreason_examples_table.py PYREASON_CHECKOUT [--timeout S]

PYREASON_CHECKOUT is a clone of github.com/lab-v2/pyreason (its examples/ folder is read, never copied
here). Each script runs in a new temporary folder (they save their traces into the current one) with
its own folder on sys.path, as `python SCRIPT` would."""
from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

# the prefix of the traces PyReason's repository commits for an example (examples/csv_outputs)
COMMITTED = {"basic_tutorial_ex.py": "basic_rule_trace",
             "cybersecurity_inconsistency_ex.py": "cybersecurity_rule_trace",
             "inconsistency_example.py": "inconsistency_example", "infer_edges_ex.py": "infer_edges_rule_trace",
             "advanced_graph_ex.py": "advanced_rule_trace"}
# differences docs/pyreason.md documents: (example, the columns that differ) -> why
DOCUMENTED = {("cybersecurity_inconsistency_ex.py", ("Clause-2",)):
              "Clause-k lists the components of the grounding that caused the row, PyReason every grounding "
              "that qualified (\"The rule trace's rows\")"}


def run_example(script: Path, timeout: float, checkout: Path) -> tuple[str, str, str]:
    """(how it ran, how its output compares, why: the last line of its error or the documented reason)."""
    with tempfile.TemporaryDirectory() as cwd:
        try:
            r = subprocess.run([sys.executable, "-m", "tracelab.pyreason", str(script)], cwd=cwd,
                               capture_output=True, text=True, timeout=timeout, check=False)
        except subprocess.TimeoutExpired:
            return "timed out", "", f"after {timeout:g} s"
        if r.returncode != 0:
            lines = [line for line in r.stderr.strip().splitlines() if line.strip()]
            last = lines[-1] if lines else f"exit status {r.returncode}"
            return "fails", "", last.replace(f"{checkout.resolve()}/", "")  # the checkout's own paths
        return ("runs unchanged",) + compare_output(script, Path(cwd), checkout)


def compare_output(script: Path, cwd: Path, checkout: Path) -> tuple[str, str]:
    prefix = COMMITTED.get(script.name)
    saved = sorted(cwd.glob("rule_trace_*.csv"))
    if prefix is None or not saved:
        if "\nassert" in script.read_text(encoding="utf-8"):
            return "same output (its asserts hold)", ""
        return "no output stated", ""
    differing: dict[str, set[str]] = {}
    counts, notes = [], []
    for kind in ("nodes", "edges"):
        committed = sorted((checkout / "examples" / "csv_outputs").glob(f"{prefix}*{kind}*.csv"))
        ours = [p for p in saved if p.name.startswith(f"rule_trace_{kind}_")]
        if not committed or not ours:
            continue
        theirs_header, theirs = read_csv(committed[-1])
        our_header, rows = read_csv(ours[-1])
        missing = [c for c in our_header if c not in theirs_header]
        if missing:
            notes.append(f"its committed {kind} trace predates the columns {', '.join(missing)}")
        shared = [c for c in theirs_header if c in our_header]
        a = [[row.get(c, "") for c in shared] for row in rows]
        b = [[row.get(c, "") for c in shared] for row in theirs]
        equal = sum(x == y for x, y in zip(a, b))
        for x, y in zip(a, b):
            differing.setdefault(kind, set()).update(c for c, u, v in zip(shared, x, y) if u != v)
        if len(a) != len(b):
            differing.setdefault(kind, set()).add(f"{len(a)} rows against {len(b)}")
        counts.append(f"{kind}: {equal} of {len(b)} rows equal")
    columns = tuple(sorted(set().union(*differing.values()))) if differing else ()
    note = "; ".join(notes)
    if not columns:
        return f"same as its committed trace ({', '.join(counts)})", note
    why = DOCUMENTED.get((script.name, columns), "not documented")
    return f"differs from its committed trace in {', '.join(columns)} ({', '.join(counts)})", "; ".join(
        filter(None, [why, note]))


def read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, encoding="utf-8", newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkout", type=Path, help="a clone of PyReason's repository")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per script (default 600)")
    args = parser.parse_args()
    scripts = sorted((args.checkout / "examples").glob("*.py"))
    if not scripts:
        print(f"no examples/*.py in {args.checkout}", file=sys.stderr)
        return 1
    print("| PyReason's example | `python -m tracelab.pyreason` | output | why not, or why it differs |")
    print("|---|---|---|---|")
    for script in scripts:
        status, output, why = run_example(script.resolve(), args.timeout, args.checkout.resolve())
        print(f"| `examples/{script.name}` | {status} | {output} | {why.replace('|', '/')} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
