"""TensorBoard, the tracker users already keep their curves in (issue 27 §3): `train --tensorboard DIR`
writes the metrics as event files while training (a resume in place continues them), `tracelab export
RUN --tensorboard DIR` converts a finished run. The event files are read back with TensorBoard's own
EventAccumulator and compared with the run's `metrics`. Without the tensorboard package the commands
say in one line how to install it."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tracelab.cli import main
from tracelab.store import open_run
from train_helpers import train_walk, walk_argv, walk_config

ROOT = Path(__file__).resolve().parent.parent
TRAINING_RUN = ROOT / "sample_runs" / "base-train"   # sealed, a real 150K-step training
PLAY_RUN = ROOT / "sample_runs" / "base"


def store_metrics(run: Path) -> dict[str, list[tuple[int, float]]]:
    con = open_run(run)
    try:
        rows = con.execute("SELECT name, step, value FROM metrics ORDER BY name, step, time").fetchall()
    finally:
        con.close()
    out: dict[str, list[tuple[int, float]]] = {}
    for name, step, value in rows:
        out.setdefault(name, []).append((step, value))
    return out


def event_scalars(log_dir: Path) -> dict[str, list[tuple[int, float]]]:
    accumulator = pytest.importorskip("tensorboard.backend.event_processing.event_accumulator")
    acc = accumulator.EventAccumulator(str(log_dir), size_guidance={accumulator.SCALARS: 0})  # 0: keep all
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def assert_same_curves(events: dict[str, list[tuple[int, float]]], store: dict[str, list[tuple[int, float]]]) -> None:
    assert set(events) == set(store)
    for name, points in store.items():
        assert [s for s, _ in events[name]] == [s for s, _ in points], name
        assert [v for _, v in events[name]] == pytest.approx([v for _, v in points], rel=1e-6), name  # float32


def test_train_writes_tensorboard_events_and_a_resume_in_place_continues_them(tmp_path, capsys):
    pytest.importorskip("tensorboard")
    run, tb = tmp_path / "walk", tmp_path / "tb"
    cfg = walk_config(steps=480, seed=11)
    assert train_walk(cfg, run, stop_at=246, tensorboard=tb / "walk") == 130   # stopped as by Ctrl-C
    assert [s for s, _ in event_scalars(tb / "walk")["epsilon"]] == [100, 200]    # written while training
    assert main(["train", "--resume", str(run), *walk_argv(), "--tensorboard", str(tb)]) == 0
    assert f"tensorboard --logdir {tb}" in capsys.readouterr().out
    events = event_scalars(tb / "walk")
    assert_same_curves(events, store_metrics(run))                   # both sessions, the `resumed` event too
    assert [s for s, _ in events["epsilon"]] == [100, 200, 300, 400, 480]
    assert events["resumed"] == [(248, 1.0)]


def test_export_converts_a_finished_run_to_tensorboard_events(tmp_path, capsys):
    pytest.importorskip("tensorboard")
    tb = tmp_path / "tb"
    assert main(["export", str(TRAINING_RUN), "--tensorboard", str(tb)]) == 0
    out = capsys.readouterr().out
    store = store_metrics(TRAINING_RUN)
    rows = sum(len(v) for v in store.values())
    assert out.startswith(f"wrote {rows:,} scalars ({len(store)} metric names, steps 2,048-150,016) to "
                          f"{tb / 'base-train'}/")
    assert_same_curves(event_scalars(tb / "base-train"), store)
    # a second export into the same place would mix two copies under one name: refused, nothing touched
    before = sorted(p.stat().st_mtime_ns for p in (tb / "base-train").iterdir())
    assert main(["export", str(TRAINING_RUN), "--tensorboard", str(tb)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (f"tracelab: error: {str(tb / 'base-train')!r} already holds TensorBoard event files: give "
                   f"another --tensorboard DIR, or remove them")
    assert sorted(p.stat().st_mtime_ns for p in (tb / "base-train").iterdir()) == before


def test_export_of_a_run_without_metrics_or_into_a_file_is_one_line(tmp_path, capsys):
    pytest.importorskip("tensorboard")
    tb = tmp_path / "tb"
    assert main(["export", str(PLAY_RUN), "--tensorboard", str(tb)]) == 1
    assert capsys.readouterr().err.strip() == (
        f"tracelab: error: {str(PLAY_RUN)!r} is a play run (games, no training metrics): export --tensorboard "
        f"converts a training run's metrics")
    assert not (tb / "base").exists()
    afile = tmp_path / "afile"
    afile.write_text("kept")
    assert main(["export", str(TRAINING_RUN), "--tensorboard", str(afile)]) == 1
    assert capsys.readouterr().err.strip() == f"tracelab: error: --tensorboard {str(afile)!r} is not a directory"
    assert afile.read_text() == "kept"


@pytest.mark.parametrize("argv", [["export", str(TRAINING_RUN)], ["train", "--total-timesteps", "64"]])
def test_without_the_tensorboard_package_the_command_says_how_to_install_it(tmp_path, argv):
    # the package made unimportable in a child interpreter (sys.modules[name] = None: import raises ImportError)
    code = ("import sys; sys.modules['tensorboard'] = None; from tracelab.cli import main; "
            f"sys.exit(main({[*argv, '--tensorboard', str(tmp_path / 'tb')]!r}))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "tracelab: error: writing TensorBoard event files needs the tensorboard package: pip install "
        "'tracelab[tensorboard]' (or pip install tensorboard)")
    assert not (tmp_path / "tb").exists() and not (tmp_path / "runs").exists()   # checked before training
