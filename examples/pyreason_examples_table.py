"""Run PyReason's own example scripts unchanged with `python -m tracelab.pyreason` and print the table of
docs/pyreason.md ("PyReason's examples, run unchanged"): per script whether it ran, and the last line of
its error when it did not.

    python examples/pyreason_examples_table.py PYREASON_CHECKOUT [--timeout S]

PYREASON_CHECKOUT is a clone of github.com/lab-v2/pyreason (its examples/ folder is read, never copied
here). Each script runs in a new temporary folder (they write their traces into the current one) with
its own folder on sys.path, as `python SCRIPT` would."""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path


def run_example(script: Path, timeout: float) -> tuple[str, str]:
    """("runs" | "fails" | "timed out", the last line of its stderr when it did not run)."""
    with tempfile.TemporaryDirectory() as cwd:
        try:
            r = subprocess.run([sys.executable, "-m", "tracelab.pyreason", str(script)], cwd=cwd,
                               capture_output=True, text=True, timeout=timeout, check=False)
        except subprocess.TimeoutExpired:
            return "timed out", f"after {timeout:g} s"
    if r.returncode == 0:
        return "runs", ""
    lines = [line for line in r.stderr.strip().splitlines() if line.strip()]
    return "fails", lines[-1] if lines else f"exit status {r.returncode}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("checkout", type=Path, help="a clone of PyReason's repository")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per script (default 600)")
    args = parser.parse_args()
    scripts = sorted((args.checkout / "examples").glob("*.py"))
    if not scripts:
        print(f"no examples/*.py in {args.checkout}", file=sys.stderr)
        return 1
    print("| PyReason's example | `python -m tracelab.pyreason` | why not |")
    print("|---|---|---|")
    for script in scripts:
        status, why = run_example(script, args.timeout)
        print(f"| `examples/{script.name}` | {status} | {why.replace('|', '/')} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
