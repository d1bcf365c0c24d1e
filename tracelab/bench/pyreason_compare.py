"""`tracelab bench pyreason`: PyReason against tracelab on the same scripts (issue 29, docs/pyreason.md,
"Switching from PyReason").

Each program is one script of examples/, written against PyReason's API with `import tracelab.pyreason as
pr`; PyReason runs the same file with that line replaced by `import pyreason as pr`, under the interpreter
of a PyReason install (--pyreason-python), and tracelab under this interpreter. Every run is a fresh
process. The first run of each side starts from empty caches, as after a fresh install:
- tracelab: NUMBA_CACHE_DIR and TRACELAB_CACHE_DIR on a new temporary folder;
- PyReason: it sets NUMBA_CACHE_DIR to a `cache` folder inside its own package and, on its first import,
  runs its hello world to fill it (its `.cache_status.yaml` says whether that was done). The package is
  copied into a temporary folder without both, and put first on PYTHONPATH, so the install itself is
  neither read for caches nor written.
The warm runs use the caches the first run filled. Each run reports wall time, CPU time (user + sys of the
process and of what it waited for), peak RSS (the process's VmHWM, written by the runner at exit) and its
RSS every SAMPLE_S seconds from /proc/PID/status (memory over time; the peak is the larger of
VmHWM and the samples), and the load average around it."""
from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tracelab.bench.biggraph import write_graph
from tracelab.bench.common import children_cpu_s, fmt_num, format_table, machine_info, summarize
from tracelab.errors import UserError
from tracelab.provenance import load_average

TRACELAB_IMPORT = "import tracelab.pyreason as pr"
PYREASON_IMPORT = "import pyreason as pr"
SAMPLE_S = 0.25
SPREAD_NODES = 2_000  # docs/benchmarks/history.md's "Big graph" size, where issue 14 measured PyReason at 268 s
SERIES_MARKS_S = (1, 2, 5, 10, 30, 60, 120, 300, 600, 1200, 2400)

# Runs a script with its first `import tracelab.pyreason as pr` replaced, as the script itself (its
# __file__, its argv), and writes the process's peak RSS at exit. Standard library only: it runs under
# PyReason's interpreter too.
RUNNER = r"""
import atexit, sys
peak_file, script, old, new = sys.argv[1:5]

def write_peak():
    with open("/proc/self/status") as status:
        peak = [line.split()[1] for line in status if line.startswith("VmHWM:")]
    with open(peak_file, "w") as out:
        out.write(peak[0] if peak else "")

atexit.register(write_peak)
with open(script, encoding="utf-8") as f:
    source = f.read()
if old not in source:
    sys.exit(f"{script}: has no line {old!r} to replace")
sys.argv = [script, *sys.argv[5:]]
exec(compile(source.replace(old, new, 1), script, "exec"), {"__name__": "__main__", "__file__": script})
"""


def examples_dir() -> Path:
    """The checkout's examples/ folder, which holds the scripts (a wheel install has none)."""
    path = Path(__file__).resolve().parents[2] / "examples"
    if not (path / "pyreason_hello_world.py").is_file():
        raise UserError(f"bench pyreason runs the scripts of a checkout's examples/ folder: not found at {path}")
    return path


PROGRAMS = ("hello", "spread")


def programs(chosen: tuple[str, ...]) -> dict[str, tuple[Path, tuple[str, ...]]]:
    """name -> (script, what its argv needs: "graph" is the spread graph the bench writes)."""
    ex = examples_dir()
    found = {"hello": ("hello world", ex / "pyreason_hello_world.py", ()),
             "spread": (f"spread, {SPREAD_NODES:,} nodes, 11 steps", ex / "pyreason_spread.py", ("graph",))}
    return {found[c][0]: found[c][1:] for c in chosen}


def check_pyreason_python(python: str) -> dict[str, str]:
    """The PyReason install behind `python`: its package folder and version, without importing it (an
    import would run PyReason's first-time initialisation in the install itself)."""
    if not Path(python).is_file():
        raise UserError(f"--pyreason-python {python}: no such file")
    probe = ("import importlib.metadata as m, importlib.util as u; s = u.find_spec('pyreason'); "
             "print(s.submodule_search_locations[0] if s else ''); print(m.version('pyreason') if s else '')")
    try:
        done = subprocess.run([python, "-P", "-c", probe], capture_output=True, text=True, timeout=120, check=False)
    except OSError as e:
        raise UserError(f"--pyreason-python {python}: cannot run it ({e.strerror})") from None
    lines = done.stdout.splitlines()
    if done.returncode != 0 or len(lines) < 2 or not lines[0]:
        raise UserError(f"--pyreason-python {python}: PyReason is not installed there (`{python} -m pip install "
                        "pyreason`)")
    return {"python": python, "package": lines[0], "version": lines[1]}


def cold_pyreason_copy(package: str, into: Path) -> Path:
    """A copy of PyReason's package without its numba cache and marked not initialised: its first import
    compiles as in a fresh install. Returns the folder to put on PYTHONPATH."""
    target = into / "pyreason"
    shutil.copytree(package, target, ignore=shutil.ignore_patterns("cache", "__pycache__"))
    (target / ".cache_status.yaml").write_text("initialized: false\n", encoding="utf-8")
    return into


def _rss_bytes(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def timed_run(command: list[str], env: dict[str, str], cwd: Path, timeout_s: float) -> dict[str, Any]:
    """One fresh process: wall, CPU, peak RSS, RSS samples, exit status, the end of its output."""
    peak_file = cwd / "peak_kb"  # the runner's first argument
    peak_file.unlink(missing_ok=True)
    out_path, err_path = cwd / "stdout.txt", cwd / "stderr.txt"
    load_before, samples = load_average(), []
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    with open(out_path, "w") as out, open(err_path, "w") as err:
        proc = subprocess.Popen([*command[:4], str(peak_file), *command[4:]], env=env, cwd=cwd,
                                stdout=out, stderr=err)
        timed_out = False
        while proc.poll() is None:
            elapsed = time.perf_counter() - t0
            rss = _rss_bytes(proc.pid)
            if rss:
                samples.append((round(elapsed, 2), rss))
            if elapsed > timeout_s:
                proc.kill()
                timed_out = True
            try:
                proc.wait(timeout=SAMPLE_S)
            except subprocess.TimeoutExpired:
                pass
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - cpu0
    peak_text = peak_file.read_text().strip() if peak_file.exists() else ""
    # the kernel updates VmHWM lazily (a sample of VmRSS has been seen 0.6% above it): the larger of both
    peak = max([int(peak_text) * 1024 if peak_text else 0, *(r for _, r in samples)])
    stdout = out_path.read_text(errors="replace").strip().splitlines()
    stderr = err_path.read_text(errors="replace").strip().splitlines()
    error = (f"timed out after {timeout_s:.0f} s" if timed_out else
             f"stopped by signal {-proc.returncode}" if proc.returncode < 0 else
             (stderr[-1] if stderr else f"exit status {proc.returncode}") if proc.returncode else None)
    return {"wall_s": wall, "cpu_s": cpu, "peak_rss_bytes": peak, "rss_samples": samples, "error": error,
            "result": stdout[-1] if stdout else "", "load_before": load_before, "load_after": load_average()}


def _side_runs(python: str, import_line: str, script: Path, args: list[str], env: dict[str, str],
               work: Path, warm_repeats: int, timeout_s: float, done: Callable[[str, dict], None]) -> dict[str, Any]:
    """The first run (env's caches empty) and `warm_repeats` runs on the caches it filled; `done(kind, run)`
    after each (a PyReason run can take many minutes: what is measured is not lost if the bench is stopped)."""
    work.mkdir(parents=True, exist_ok=True)
    command = [python, "-P", "-c", RUNNER, str(script), TRACELAB_IMPORT, import_line, *args]
    first = timed_run(command, env, work, timeout_s)
    done("first run", first)
    warm = []
    for _ in range(0 if first["error"] else warm_repeats):
        warm.append(timed_run(command, env, work, timeout_s))
        done("warm", warm[-1])
    return {"first": first, "warm": warm,
            "warm_wall_s": summarize([r["wall_s"] for r in warm]).to_dict() if warm else None,
            "warm_cpu_s": summarize([r["cpu_s"] for r in warm]).to_dict() if warm else None}


def run(quick: bool, repeats: int, pyreason_python: str | None, timeout_s: float,
        chosen: tuple[str, ...] = PROGRAMS, cache_dir: Path | None = None,
        progress: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """Each chosen program (--quick: the hello world) under tracelab, then (with `pyreason_python`) under
    PyReason; see the docstring. Each program's caches start empty in a temporary folder; with `cache_dir`
    every program uses that folder's (made if missing, kept afterwards), and a first run that finds them
    filled by an earlier run is marked `"first_cold": false`. `progress` receives each run as it ends, with
    its program, side and kind."""
    pyreason = check_pyreason_python(pyreason_python) if pyreason_python else None
    warm_repeats = 1 if quick else repeats
    result: dict[str, Any] = {"pyreason": pyreason, "warm_repeats": warm_repeats, "programs": {},
                              "cache_dir": str(cache_dir) if cache_dir else None, "load_before": load_average()}
    with tempfile.TemporaryDirectory(prefix="tracelab-bench-pyreason-") as tmp_text:
        tmp = Path(tmp_text)
        for i, (name, (script, needs)) in enumerate(programs(PROGRAMS[:1] if quick else chosen).items()):
            caches = cache_dir or tmp / f"program{i}"
            args = []
            if "graph" in needs:
                graph = tmp / f"spread_{SPREAD_NODES}.graphml"
                write_graph(graph, SPREAD_NODES)  # seeded: the same graph every time
                args.append(str(graph))
            sides: dict[str, Any] = {}

            def done(kind: str, r: dict[str, Any], program: str = name, side: str = "tracelab") -> None:
                if progress:
                    progress({"program": program, "side": side, "kind": kind, **r})
            numba_cache = caches / "tracelab-cache" / "numba"
            cold = not numba_cache.is_dir() or not any(numba_cache.iterdir())
            tl_env = {**os.environ, "NUMBA_CACHE_DIR": str(numba_cache),
                      "TRACELAB_CACHE_DIR": str(caches / "tracelab-cache" / "tracelab")}
            sides["tracelab"] = {"first_cold": cold, **_side_runs(
                sys.executable, TRACELAB_IMPORT, script, args, tl_env, tmp / f"tl{i}", warm_repeats, timeout_s, done)}
            if pyreason:
                site = caches / "pyreason-site"
                cold = not (site / "pyreason").is_dir()
                if cold:
                    cold_pyreason_copy(pyreason["package"], site)
                pr_env = {**os.environ, "PYTHONPATH": str(site)}
                sides["pyreason"] = {"first_cold": cold, **_side_runs(
                    pyreason["python"], PYREASON_IMPORT, script, args, pr_env, tmp / f"pr{i}", warm_repeats,
                    timeout_s, functools.partial(done, side="pyreason"))}
            result["programs"][name] = {"script": str(script.relative_to(script.parents[1])), "args": needs,
                                        **sides}
    result["load_after"] = load_average()
    result["machine"] = machine_info()
    result["pythondontwritebytecode"] = bool(os.environ.get("PYTHONDONTWRITEBYTECODE"))
    return result


def rss_series(samples: list[tuple[float, int]]) -> str:
    """RSS (MB) at 1, 2, 5, 10, 30 ... s while the process ran, and at its last sample."""
    points = []
    for mark in SERIES_MARKS_S:
        before = [rss for t, rss in samples if t <= mark]
        if not before or mark > samples[-1][0]:
            break
        points.append(f"{mark}s {before[-1] / 2**20:.0f}")
    if samples:
        points.append(f"end ({samples[-1][0]:.0f}s) {samples[-1][1] / 2**20:.0f}")
    return ", ".join(points)


def _row(program: str, side: str, kind: str, r: dict[str, Any], wall: str, cpu: str) -> tuple:
    return (program, side, kind, wall, cpu, f"{r['peak_rss_bytes'] / 2**20:.0f}",
            r["error"] or r["result"], "/".join(f"{x:.1f}" for x in r["load_before"][:1] + r["load_after"][:1]))


def report(r: dict[str, Any]) -> str:
    rows, series = [], []
    for program, p in r["programs"].items():
        for side in ("pyreason", "tracelab"):
            if side not in p:
                continue
            s = p[side]
            first = s["first"]
            kind = "first run" if s.get("first_cold", True) else "first run, caches filled before"
            rows.append(_row(program, side, kind, first, fmt_num(first["wall_s"]), fmt_num(first["cpu_s"])))
            series.append(f"{program}, {side}, {kind}: {rss_series(first['rss_samples'])}")
            if s["warm"]:
                w, c = s["warm_wall_s"], s["warm_cpu_s"]
                last = s["warm"][-1]
                rows.append(_row(program, side, f"warm (median of {len(s['warm'])})", last,
                                 f"{fmt_num(w['median'])} ({fmt_num(w['min'])}-{fmt_num(w['max'])})",
                                 f"{fmt_num(c['median'])} ({fmt_num(c['min'])}-{fmt_num(c['max'])})"))
                series.append(f"{program}, {side}, warm: {rss_series(last['rss_samples'])}")
    who = (f"PyReason {r['pyreason']['version']} ({r['pyreason']['python']})" if r["pyreason"] else
           "PyReason not run (no --pyreason-python)")
    lines = [f"{who} against tracelab {r['machine']['versions'].get('tracelab')}; every run a fresh process; "
             f"load average before: {', '.join(map(str, r['load_before']))}, after: "
             f"{', '.join(map(str, r['load_after']))}",
             format_table(["program", "engine", "run", "wall s", "CPU s (user+sys)", "peak RSS MB",
                           "result (last line printed) or error", "load 1 min, start/end"], rows),
             f"RSS over time (MB, sampled every {SAMPLE_S} s; warm: the last warm run):", *series]
    return "\n".join(lines)


def plot(r: dict[str, Any], path: Path) -> None:
    """RSS over time of every run, one panel per program (matplotlib, imported only here)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(r["programs"])
    fig, axes = plt.subplots(1, len(names), figsize=(6.5 * len(names), 4.2), squeeze=False)
    colors = {"pyreason": "tab:red", "tracelab": "tab:blue"}
    for ax, name in zip(axes[0], names):
        for side in ("pyreason", "tracelab"):
            if side not in r["programs"][name]:
                continue
            runs = r["programs"][name][side]
            first = "first run" if runs.get("first_cold", True) else "first run, caches filled before"
            for kind, run_, style in ((first, runs["first"], "-"),
                                      ("warm", runs["warm"][-1] if runs["warm"] else None, "--")):
                if run_ and run_["rss_samples"]:
                    t = [max(s[0], SAMPLE_S) for s in run_["rss_samples"]]
                    ax.plot(t, [s[1] / 2**20 for s in run_["rss_samples"]], style, color=colors[side],
                            label=f"{side}, {kind} ({run_['wall_s']:.1f} s)")
        ax.set_xscale("log")
        ax.set_xlabel("seconds since the process started (log scale)")
        ax.set_ylabel("resident memory, MB")
        ax.set_title(name)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    loads = [x["load_before"][0] for p in r["programs"].values() for side in ("pyreason", "tracelab")
             if side in p for x in (p[side]["first"], *p[side]["warm"]) if x["load_before"]]
    said = f", load average (1 min) {min(loads):.1f}-{max(loads):.1f} at the runs' starts" if loads else ""
    fig.suptitle(f"RSS every {SAMPLE_S} s; {os.cpu_count()} cores{said}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def merge(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Several runs of the bench (e.g. one per --program) as one result: the programs of all, the load
    before the first and after the last."""
    merged = {**results[0], "programs": {}}
    for r in results:
        merged["programs"].update(r["programs"])
    merged["load_after"] = results[-1]["load_after"]
    return merged


if __name__ == "__main__":  # python -m tracelab.bench.pyreason_compare OUT.png RESULT.json ... (from --json)
    import json
    plot(merge([json.loads(Path(f).read_text()) for f in sys.argv[2:]]), Path(sys.argv[1]))
