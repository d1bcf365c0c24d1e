"""Where a figure or a result was made: the source commit and the machine. One place for what the
benchmarks (bench/common.py) and the experiment reports (train/experiments/report.py) record beside
their figures."""
from __future__ import annotations

import os
import platform
import subprocess
from pathlib import Path

_SOURCE = Path(__file__).resolve().parent  # git answers for the checkout that holds this package
GIT_TIMEOUT_S = 5  # a hung git (a network filesystem) must not hang a benchmark or a report


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=_SOURCE, capture_output=True, text=True, check=True,
                          timeout=GIT_TIMEOUT_S).stdout.strip()


def source_commit() -> str | None:
    """The commit of the checkout this package runs from, with " (with uncommitted changes)" when tracked
    files differ from it; None outside a git checkout (an installed package) or without git."""
    try:
        head = _git("rev-parse", "HEAD")
        dirty = _git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return None
    return (head + (" (with uncommitted changes)" if dirty else "")) or None


def cpu_model() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo), else what the platform says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages (empty where the platform has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return []


def machine_summary(load_when: str = "") -> str:
    """One line: cores, CPU, system and the 1-minute load average, followed by `load_when` ("at the end")."""
    load = load_average()
    said = f", load average {load[0]:.1f}" + (f" {load_when}" if load_when else "") if load else ""
    return f"{os.cpu_count()} cores, {cpu_model()}, {platform.system()} {platform.release()}{said}"
