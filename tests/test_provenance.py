"""Where figures were made (tracelab/provenance.py): the benchmarks and the experiment reports name the
commit and the machine the same way, from one place."""
from __future__ import annotations

import os
import subprocess

from tracelab.bench.common import machine_info
from tracelab.provenance import cpu_model, machine_summary, source_commit
from tracelab.train.experiments import run

from tracelab import provenance


def test_the_benchmarks_and_the_reports_name_the_same_commit() -> None:
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=provenance._SOURCE, capture_output=True,
                          text=True, check=True).stdout.strip()
    commit = source_commit()
    assert commit is not None and commit.startswith(head)  # the whole hash, dirty or not
    assert machine_info()["commit"] == commit == run.commit()


def test_the_machine_line_names_cores_cpu_and_load() -> None:
    line = machine_summary("at the end")
    assert line.startswith(f"{os.cpu_count()} cores, {cpu_model()}, ")
    assert line.endswith(" at the end") and ", load average " in line
    assert run.machine().split(", load average")[0] == line.split(", load average")[0]
    assert machine_info()["cpu"] == cpu_model()


def test_outside_a_checkout_the_commit_is_unknown(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(provenance, "_SOURCE", tmp_path)  # a folder git knows nothing of
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path.parent))
    assert source_commit() is None
    assert run.commit() == "unknown (not a git checkout)"
