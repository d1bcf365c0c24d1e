"""The README's TUI pictures show real runs: nothing in the library writes metrics except a training (or
an evaluation), and `tracelab tui --screenshots` photographs a training run from disk, refusing a run
without metrics instead of drawing curves of its own."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tracelab.cli import main

ROOT = Path(__file__).resolve().parent.parent
# where metrics may be written: the store's writer (the method), training, evaluation, experiments, and
# the resume event of `train` and `train --env` (commands/_training.say_resumed)
METRIC_WRITERS = {"tracelab/store/writer.py", "tracelab/commands/_training.py"}
METRIC_WRITER_DIRS = ("tracelab/train/",)


def test_no_code_outside_training_writes_metrics() -> None:
    writers = []
    for folder in ("tracelab", "engine", "viewers"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in METRIC_WRITERS or rel.startswith(METRIC_WRITER_DIRS):
                continue
            if re.search(r"write_metrics\(|INSERT\s+INTO\s+metrics", path.read_text(), re.IGNORECASE):
                writers.append(rel)
    assert writers == [], f"metrics written outside a training: {writers}"


def test_screenshots_refuse_a_training_picture_of_a_run_without_metrics(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "shots"
    code = main(["tui", "--screenshots", str(out), str(ROOT / "sample_runs" / "advanced"),
                 str(ROOT / "sample_runs" / "base")])
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith("tracelab: error: ") and err.count("\n") == 1, err
    assert "sample_runs/base" in err and "no training metrics" in err
    assert not out.exists()  # refused before anything was photographed


def test_the_training_picture_defaults_to_the_sample_training_run() -> None:
    from tracelab.viewers.tui import screenshots
    assert not hasattr(screenshots, "write_training_run")
    assert screenshots.training_run_problem(ROOT / "sample_runs" / "base-train") is None
