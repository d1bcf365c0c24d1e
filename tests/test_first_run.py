"""A newcomer's first run (issue 31 part 4): `tracelab play` on an empty numba cache, told to compile
first (TRACELAB_COLD_START=wait, as its background compile runs), compiles each kernel once, for one
signature, and says so in one line; the next run loads them and says nothing. GridWar plays through
its spec (rules/gridworld/war.toml): the engine's kernels and the declared world's (its fused step,
observation reads, nearest-thing loop). Times are measured by `tracelab bench first-run`, never here."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

# a play in this process, then what numba holds: each kernel function's signatures, per module
PROBE = r"""
import json, sys
from numba.core.registry import CPUDispatcher
from tracelab.cli import main
code = main(["play", "--scenario", "advanced", "--episodes", "2", "--run", sys.argv[1]])
import tracelab.engine.kernel as K
import tracelab.engine.lanes as L
from tracelab.envs.declared import computed, fused, observe_kernel

def signatures(*modules):
    return {f"{m.__name__.rsplit('.', 1)[-1]}.{n}": len(v.signatures) for m in modules for n, v in vars(m).items()
            if isinstance(v, CPUDispatcher) and v.py_func.__module__ == m.__name__ and v.signatures}

print(json.dumps({"code": code, "kernel": signatures(K), "declared": signatures(computed, fused, observe_kernel),
                  "lanes": signatures(L)}))
"""


def _play(cache: Path, run_dir: Path) -> tuple[dict, list[str]]:
    """The probe, run from a folder holding another `tracelab/` (as in another checkout): the second
    process must still run this tracelab's code."""
    decoy = cache / "elsewhere"
    (decoy / "tracelab").mkdir(parents=True, exist_ok=True)
    (decoy / "tracelab" / "__init__.py").write_text("raise ImportError('another tracelab')\n")
    # compiled before the first step (a cold play's default is to play at once: tests/test_first_run_python.py)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache / "numba"), "TRACELAB_CACHE_DIR": str(cache / "tracelab"),
           "TRACELAB_COLD_START": "wait"}
    done = subprocess.run([sys.executable, "-P", "-c", PROBE, str(run_dir)], env=env, capture_output=True,
                          text=True, timeout=900, check=False, cwd=decoy)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.splitlines()[-1]), done.stderr.splitlines()


def test_a_first_play_compiles_each_kernel_once_and_says_so_in_one_line(tmp_path: Path) -> None:
    got, err = _play(tmp_path, tmp_path / "cold")
    assert got["code"] == 0
    # one signature per function: a constant argument no longer compiles a callee again (kernel.py's docstring)
    assert got["kernel"]["kernel.step_worlds"] == 1
    assert {n: c for n, c in got["kernel"].items() if c != 1} == {}
    assert got["declared"]["fused.fused_step"] == 1  # the world's step, fused with the engine's
    assert {n: c for n, c in got["declared"].items() if c != 1} == {}
    assert got["lanes"] == {}  # one world: the counting kernel only, the lanes kernel never compiles
    notice = [ln for ln in err if "compiling" in ln]
    assert len(notice) == 1, err  # one line, once
    assert notice[0].startswith("tracelab: compiling the rule engine's step kernel and a declared world's step"), notice
    assert "war.toml (first run only" in notice[0]

    again, err = _play(tmp_path, tmp_path / "warm")  # the next run loads everything: nothing said
    assert again["code"] == 0 and not [ln for ln in err if "compiling" in ln], err
    loaded = {**again["kernel"], **again["declared"]}  # the entry points, loaded for the signatures compiled cold
    assert loaded and all(got["kernel"].get(n, got["declared"].get(n)) == c == 1 for n, c in loaded.items()), loaded
