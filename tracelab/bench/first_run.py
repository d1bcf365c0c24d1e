"""`tracelab bench first-run`: what a newcomer waits for (issues 31 part 4, 40). Every first compile a user
can meet runs in a fresh process on empty caches, as after a fresh install (numba's through
NUMBA_CACHE_DIR, tracelab's compile cache through TRACELAB_CACHE_DIR, both in a temporary folder: the
user's own caches are neither read nor touched), then once more on the caches it filled, as every later
run does:

- `play`: the README's main command, `tracelab play --scenario advanced --episodes 5` (the war game through its
  spec, rules/gridworld/war.toml: the engine's kernels and the declared world's fused step). Cold, it plays
  on the kernels' Python source while a background process compiles them (tracelab/commands/_cold_start.py):
  its figures are the play's, and `cold_ready_s` is how long after its start that process had filled the
  cache (waited for before the warm run);
- `reason-small`, `reason-large`: `tracelab reason` of reach.rules (5 lines: the reference evaluator) and of
  the supply chain over its 2,430-node graph (the compiled engine);
- `spec-env`, `spec-vector-env`: a declared world's gymnasium env (`make_env`) and vector env (`make_vec_env`,
  8 worlds) built, reset and stepped once (FrozenLake's spec);
- `train`: `tracelab train --scenario base` up to its first learner updates (a 600-step budget).

Each phase has its own empty caches (what a user meets when it is their first command). Each figure is
the median of --repeats such pairs: wall time, and CPU time (user + sys of the command and of every
process it waited for), which the other load of a shared machine inflates far less than wall time.
`--fresh-venv`: the commands run in a new venv (`--system-site-packages`, the project installed into it
without dependencies and without its .pyc files), so that Python's bytecode cache is as cold as numba's.
`--write-figures`: the cold figures go into tracelab/first_run_figures.json, which the compile notices quote
(tracelab/first_run_figures.py). The load average before and after is part of the result."""
from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from tracelab.bench.common import children_cpu_s, format_table, machine_info, summarize
from tracelab.provenance import load_average

ROOT = Path(__file__).resolve().parents[2]
_ENV_STEP = ("import logging, numpy as np; logging.basicConfig(level=logging.INFO, format='%(message)s'); "
             "from tracelab.envs import {make}; e = {make}({spec!r}{n}); "
             "e.reset(seed=0); e.step({action}); print('stepped')")


def phases(root: Path) -> tuple[tuple[str, str, tuple[str, ...]], ...]:
    """(name, what runs, argv after the interpreter: `-m tracelab ...` or `-c ...`; RUN: the run folder) of
    each phase, on the source tree at `root`."""
    examples, spec = root / "rules" / "examples", str(root / "rules" / "toytext" / "frozen_lake.toml")
    return (
        ("play", "tracelab play --scenario advanced --episodes 5",
         ("-m", "tracelab", "play", "--scenario", "advanced", "--episodes", "5", "--run", "RUN")),
        ("reason-small", "tracelab reason rules/examples/reach.rules --steps 5",
         ("-m", "tracelab", "reason", str(examples / "reach.rules"), "--steps", "5")),
        ("reason-large", "tracelab reason rules/examples/supply_chain.rules --graph ...supply_chain.graphml --steps 8",
         ("-m", "tracelab", "reason", str(examples / "supply_chain.rules"), "--graph",
          str(examples / "supply_chain.graphml"), "--steps", "8")),
        ("spec-env", "make_env(frozen_lake.toml): reset, one step",
         ("-c", _ENV_STEP.format(make="make_env", spec=spec, n="", action="0"))),
        ("spec-vector-env", "make_vec_env(frozen_lake.toml, 8): reset, one step",
         ("-c", _ENV_STEP.format(make="make_vec_env", spec=spec, n=", 8", action="np.zeros(8, np.int64)"))),
        ("train", "tracelab train --scenario base --total-timesteps 600 --learning-starts 500",
         ("-m", "tracelab", "train", "--scenario", "base", "--total-timesteps", "600", "--learning-starts", "500",
          "--eval-every", "100000", "--run", "RUN")),
    )


PHASES = [name for name, _, _ in phases(ROOT)]
QUICK_PHASES = ("reason-small", "spec-env")
FIGURES = Path(__file__).resolve().parents[1] / "first_run_figures.json"
TIMEOUT_S = 1800  # a cold compile on a loaded machine has taken 3 minutes of wall time


def timed(python: str, argv: tuple[str, ...], cache_dir: str, run_dir: str) -> dict[str, Any]:
    """One command in a fresh process with its caches in `cache_dir`: wall and CPU seconds, and the
    notices it printed (the lines of stderr that say `compiling`)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": os.path.join(cache_dir, "numba"),
           "TRACELAB_CACHE_DIR": os.path.join(cache_dir, "tracelab")}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # a user's Python writes its .pyc files
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    done = subprocess.run([python, "-P", *[run_dir if a == "RUN" else a for a in argv]], env=env, cwd=cache_dir,
                          capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - cpu0
    if done.returncode != 0:
        raise RuntimeError(f"`{' '.join(argv)}` failed (exit {done.returncode}):\n{done.stderr[-2000:]}")
    notice = [ln for ln in done.stderr.splitlines() if "compiling" in ln or "first run" in ln]
    background = re.search(r"background process \(pid (\d+)\)", done.stderr)  # a cold play's compile
    ready_s = _wait_for(int(background.group(1))) + wall if background else None
    return {"wall_s": wall, "cpu_s": cpu, "notice": notice, "ready_s": ready_s}


def _wait_for(pid: int) -> float:
    """Seconds until process `pid` (not a child of this one: its own session) has ended (the next phase
    must find the cache it fills)."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < TIMEOUT_S:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    return time.perf_counter() - t0


@contextmanager
def interpreter(fresh_venv: bool) -> Iterator[tuple[str, Path]]:
    """This Python and source tree, or a new venv with a copy of the tree (no .pyc files: Python's bytecode
    cache as cold as numba's) installed in it as the README installs it (editable: the game's rules and the
    examples stay in the tree; a plain install leaves rules/ out), without deps."""
    if not fresh_venv:
        yield sys.executable, ROOT
        return
    with tempfile.TemporaryDirectory(prefix="tracelab-first-run-venv-") as tmp:
        venv, root = os.path.join(tmp, "venv"), Path(tmp) / "tracelab"
        shutil.copytree(ROOT, root, ignore=shutil.ignore_patterns(".git", ".venv", "__pycache__", "*.egg-info",
                                                                   "build", "runs"))
        subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", venv], check=True, timeout=600)
        python = os.path.join(venv, "bin", "python")
        done = subprocess.run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-compile", "-e", str(root)],
                              timeout=1200, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"installing {root} into a fresh venv failed:\n{done.stderr[-2000:]}")
        yield python, root


def run(quick: bool, repeats: int, fresh_venv: bool = False, only: list[str] | None = None) -> dict[str, Any]:
    unknown = sorted(set(only or []) - set(PHASES))
    if unknown:
        raise ValueError(f"bench first-run: no phase {', '.join(unknown)} (phases: {', '.join(PHASES)})")
    repeats = 1 if quick else repeats
    load_before = load_average()
    measured: dict[str, Any] = {}
    with interpreter(fresh_venv) as (python, root):
        chosen = [p for p in phases(root) if (p[0] in only if only else (p[0] in QUICK_PHASES or not quick))]
        for name, what, argv in chosen:
            cold, warm = [], []
            for _ in range(repeats):
                with tempfile.TemporaryDirectory(prefix="tracelab-first-run-") as tmp:
                    cold.append(timed(python, argv, tmp, os.path.join(tmp, "run-cold")))
                    warm.append(timed(python, argv, tmp, os.path.join(tmp, "run-warm")))
            measured[name] = {"command": what,
                            **{f"{which}_{figure}": summarize([r[figure] for r in runs]).to_dict()
                               for which, runs in (("cold", cold), ("warm", warm)) for figure in ("wall_s", "cpu_s")},
                            "cold_notice": cold[0]["notice"], "warm_notice": warm[0]["notice"]}
            ready = [r["ready_s"] for r in cold if r["ready_s"] is not None]
            if ready:  # from the cold command's start until its background compile had filled the cache
                measured[name]["cold_ready_s"] = summarize(ready).to_dict()
    return {"repeats": repeats, "fresh_venv": fresh_venv, "phases": measured,
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "load_before": load_before, "load_after": load_average(), "machine": machine_info()}


def write_figures(r: dict[str, Any], path: Path = FIGURES) -> None:
    """The cold figures the compile notices quote (tracelab/first_run_figures.py reads them)."""
    figures = {name: {"wall_s": round(p["cold_wall_s"]["median"], 1), "cpu_s": round(p["cold_cpu_s"]["median"], 1)}
               for name, p in r["phases"].items()}
    table = {"measured": r["date"], "by": "tracelab bench first-run" + (" --fresh-venv" if r["fresh_venv"] else ""),
             "load": [r["load_before"], r["load_after"]], "cores": os.cpu_count(), "figures": figures}
    path.write_text(json.dumps(table, indent=1) + "\n")


def report(r: dict[str, Any]) -> str:
    rows = [(name, p[f"{which}_wall_s"]["median"], p[f"{which}_cpu_s"]["median"], which)
            for name, p in r["phases"].items() for which in ("cold", "warm")]
    load = ", ".join(map(str, r["load_before"])) or "?"
    lines = [f"bench first-run {r['date']}, medians of {r['repeats']} (cold: empty caches, as a fresh install"
             f"{', in a fresh venv' if r['fresh_venv'] else ''}; warm: the caches it filled); load average "
             f"before: {load}, after: {', '.join(map(str, r['load_after']))}",
             format_table(["phase", "wall s", "CPU s (user+sys)", "caches"], rows)]
    for name, p in r["phases"].items():
        lines.append(f"{name}: {p['command']}; notice cold: " + (" / ".join(p["cold_notice"]) or "(none)"))
        if "cold_ready_s" in p:
            lines.append(f"  its background compile had filled the cache {p['cold_ready_s']['median']:.1f} s after "
                         "the cold command started")
        if p["warm_notice"]:
            lines.append(f"  notice warm (there should be none): {' / '.join(p['warm_notice'])}")
    return "\n".join(lines)
