"""What every benchmark shares: a median-of-repeats timer, summaries with their spread, calibrated step
blocks, a record of the machine (cores, load, versions) and an aligned text table."""
from __future__ import annotations

import os
import platform
import resource
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import psutil

import tracelab

from tracelab.provenance import cpu_model, load_average, source_commit


@dataclass(frozen=True)
class Summary:
    """Repeated measurements of one figure: the median, the extremes and the spread ((max-min)/median)."""
    median: float
    min: float
    max: float
    spread: float
    runs: list[float]

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def summarize(values: Sequence[float]) -> Summary:
    """The Summary of `values` (at least one)."""
    if not values:
        raise ValueError("summarize needs at least one value")
    vals = [float(v) for v in values]
    med = statistics.median(vals)
    spread = (max(vals) - min(vals)) / med if med > 0 else 0.0
    return Summary(med, min(vals), max(vals), spread, vals)


def median_of(fn: Callable[[], object], repeats: int) -> Summary:
    """Call `fn` `repeats` times; the Summary of its wall-clock durations in seconds."""
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return summarize(times)


def rates(durations: Summary, units: float) -> Summary:
    """`units` per second for each duration of `durations` (e.g. steps/s from seconds per block)."""
    return summarize([units / d for d in durations.runs])


def calibrate(run: Callable[[int], object], target_s: float, min_units: int = 3,
              max_units: int = 1_000_000) -> int:
    """How many units (steps) make one timed block of about `target_s` seconds. Runs `run(k)` for growing
    k until a block takes a tenth of the target; doubles as the warm-up of what is measured."""
    k = 1
    while True:
        t0 = time.perf_counter()
        run(k)
        dt = time.perf_counter() - t0
        if dt >= target_s / 10 or k >= max_units:
            break
        k *= 4
    return int(min(max_units, max(min_units, k * target_s / max(dt, 1e-9))))


def rss_bytes(pid: int | None = None) -> int:
    """The resident set size of this process, or of process `pid`."""
    return int(psutil.Process(pid).memory_info().rss)


def sampled_child_rss(argv: Sequence[str], every_s: float = 1.0, timeout_s: float = 4 * 3600) -> dict[str, Any]:
    """Run `argv` in a child process, sampling its resident memory every `every_s` seconds until it exits:
    `rss_mb` [(seconds since start, MB)], `peak_mb` (the child's own VmHWM, from wait4), `seconds`,
    `returncode`, `stderr` (its last 2,000 characters). A child still running after `timeout_s` is
    killed (returncode -9)."""
    with tempfile.TemporaryFile() as err:
        child = subprocess.Popen(list(argv), stdout=subprocess.DEVNULL, stderr=err)
        t0 = time.perf_counter()
        samples: list[tuple[float, float]] = []
        while True:
            waited, status, usage = os.wait4(child.pid, os.WNOHANG)
            if waited:
                break
            elapsed = time.perf_counter() - t0
            if elapsed > timeout_s:
                child.kill()
                waited, status, usage = os.wait4(child.pid, 0)
                break
            try:
                rss = rss_bytes(child.pid)
            except psutil.NoSuchProcess:  # exited between the wait and the read
                rss = 0
            if rss:  # 0: it exited between the wait and the read, and is a zombie until waited for
                samples.append((elapsed, rss / 2**20))
            time.sleep(every_s)
        child.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        stderr = err.read().decode(errors="replace")[-2000:]
    return {"rss_mb": samples, "peak_mb": usage.ru_maxrss / 1024, "seconds": time.perf_counter() - t0,
            "returncode": child.returncode, "stderr": stderr}


def children_cpu_s() -> float:
    """User + sys seconds of every child process this one has waited for (and of theirs): the difference
    around a subprocess is its CPU time, the processes it waited for included."""
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def high_water_bytes() -> int:
    """This process's peak resident memory: VmHWM, which exec starts afresh (ru_maxrss keeps the peak of
    the process that forked it, here the bench's own ~1 GB)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # no /proc: an upper bound


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def machine_info() -> dict[str, Any]:
    """Where the figures were taken: cores, load, memory, CPU, versions, the commit."""
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cores": os.cpu_count(), "usable_cores": affinity, "load_average": load_average(),
        "memory_gb": round(psutil.virtual_memory().total / 2**30, 1), "cpu": cpu_model(),
        "platform": platform.platform(), "python": platform.python_version(),
        "versions": {d: _version(d) for d in ("tracelab", "numpy", "numba", "duckdb", "gymnasium")},
        "numba_cache_dir": os.environ.get("NUMBA_CACHE_DIR"), "commit": source_commit(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def fmt_num(v: float | int | None, digits: int = 3) -> str:
    """A number for a table: thousands separators for large values, `digits` significant figures else."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int) or abs(v) >= 1000:
        return f"{v:,.0f}"
    return f"{v:.{digits}g}"


def format_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """An aligned text table: numbers right-aligned (formatted by fmt_num), text left-aligned."""
    cells = [[c if isinstance(c, str) else fmt_num(c) for c in r] for r in rows]
    numeric = [all(not isinstance(r[i], str) for r in rows) if rows else False for i in range(len(headers))]
    widths = [max([len(h), *(len(r[i]) for r in cells)]) for i, h in enumerate(headers)]

    def line(vals: Sequence[str]) -> str:
        return "  ".join(v.rjust(w) if num else v.ljust(w)
                         for v, w, num in zip(vals, widths, numeric)).rstrip()

    return "\n".join([line(headers), "  ".join("-" * w for w in widths), *(line(r) for r in cells)])


def block_rates(run: Callable[[int], object], repeats: int, target_s: float) -> dict[str, Any]:
    """Units/s of `run(k)` (k units per call): a calibrated block size, then `repeats` timed blocks."""
    block = calibrate(run, target_s)
    run(block)  # warm-up at full size
    return {"steps_per_repeat": block, "steps_per_s": rates(median_of(lambda: run(block), repeats),
                                                             block).to_dict()}


def sample_runs_dir() -> Path:
    """The source checkout's sample_runs/ (the benches that time the reading commands and the TUI read them)."""
    runs = Path(tracelab.__file__).resolve().parents[1] / "sample_runs"
    if not (runs / "advanced").is_dir():
        raise FileNotFoundError(f"bench cli reads the sample runs of a source checkout; {runs} has none")
    return runs
