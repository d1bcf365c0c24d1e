"""bench.tree_ab steps bench env's loop in two interpreters in turn (this tree's and another's) and pairs
their CPU times; here both are this tree's python."""
from __future__ import annotations

import subprocess
import sys

from tracelab.bench.tree_ab import compare


def test_two_processes_step_in_turn_and_give_each_trees_rate() -> None:
    row = compare(sys.executable, agents=1, worlds=1, steps=20, rounds=2, trace=True)
    assert row["this_env_steps_per_cpu_s"] > 0 and row["other_env_steps_per_cpu_s"] > 0
    assert row["this_over_other"] > 0 and row["rounds"] == 2


def test_another_python_that_is_not_there_is_one_line() -> None:
    done = subprocess.run([sys.executable, "-m", "tracelab.bench.tree_ab", "--other", "/nonexistent/python",
                           "--agents", "1"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].endswith("--other /nonexistent/python: No such file or directory")
    assert "Traceback" not in done.stderr
