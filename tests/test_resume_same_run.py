"""`tracelab train --resume RUN` continues RUN itself (issue 27 §2): one run whose curves go on from the
checkpoint, the interruption a `resumed` metric row, meta.json running again then finished; `--run NEW`
branches; `--total-timesteps` raises the budget; a run with nothing left to train says so; a sealed run
is refused with the way to branch."""
from __future__ import annotations

import subprocess
import sys

from tracelab.cli import main
from tracelab.store import run_info
from tracelab.store.seal import seal_run
from tracelab.train.env_checkpoint import checkpoint_config, checkpoint_path, load_env_checkpoint
from tracelab.train.memory import memory_limit
from tracelab.train.torch_files import load_tensors
from train_helpers import ctrl_c_once_training, run_rows, train_walk, walk_argv, walk_config, walk_source


def _steps_of(run, name: str) -> list[int]:
    return [s for (s,) in run_rows(run, f"SELECT step FROM metrics WHERE name = '{name}' ORDER BY step")]


def load_checkpoint(run) -> dict:
    return load_tensors(checkpoint_path(run), 10**9)


def _error_line(capsys, status: int) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and err and err[-1].startswith("tracelab: error: ") and "Traceback" not in "".join(err)
    return err[-1]


def test_resume_continues_the_same_run_after_a_stop(tmp_path, capsys):
    run = tmp_path / "run"
    cfg = walk_config(steps=480, seed=11)
    assert train_walk(cfg, run, stop_at=246) == 130  # stops as Ctrl-C would, at step 248
    before = run_rows(run, "SELECT count(*) FROM episodes")[0][0]
    assert main(["train", "--resume", str(run), *walk_argv()]) == 0
    assert not list(tmp_path.glob("run-from-*"))  # no second run
    info = run_info(run)
    assert info.status == "finished"
    # the curve continues: every log point once, no gap, none repeated
    assert _steps_of(run, "epsilon") == [100, 200, 300, 400, 480]
    assert _steps_of(run, "eval/win_rate") == [200, 400, 480]
    # the interruption is an event the curves and sql show, and meta.json records it
    assert run_rows(run, "SELECT step, value FROM metrics WHERE name = 'resumed'") == [(248, 1.0)]
    assert [(r["step"], r["after"]) for r in info.meta["resumes"]] == [(248, "interrupted")]
    # episodes: ids never repeat; the games under way at the stop go on under new ids naming the old one
    total, distinct = run_rows(run, "SELECT count(*), count(DISTINCT episode) FROM episodes")[0]
    assert total == distinct > before
    continued = run_rows(run, "SELECT json_extract(begin_info, '$.continues') FROM episodes "
                           "WHERE json_extract(begin_info, '$.continues') IS NOT NULL")
    aborted = {e for (e,) in run_rows(run, "SELECT episode FROM episodes WHERE outcome = 'aborted' "
                                        "AND train_step < 248")}
    assert continued and {int(c) for (c,) in continued} <= aborted
    assert load_checkpoint(run)["step"] == 480


def test_ctrl_c_then_resume_gives_one_run_whose_metrics_continue(tmp_path):
    """A real Ctrl-C of `tracelab train` in a subprocess, then --resume: one run, metrics past the
    checkpoint continue without overlap, status running while it trains and finished at the end."""
    run = tmp_path / "run"
    common = ["--log-every", "64", "--eval-every", "0", "--learning-starts", "64", "--num-envs", "4",
              "--eval-games", "4", "--eval-envs", "4", "--trace-eval-games", "2", "--buffer-size", "5000",
              "--batch-size", "32"]
    status, _, _ = ctrl_c_once_training(["train", "--scenario", "base", "--total-timesteps", "100000000", *common,
                                         "--run", str(run)], run)
    assert status == 130 and run_info(run).status == "interrupted"
    # --scenario base trains through its spec: env_checkpoint's format
    stopped = load_tensors(checkpoint_path(run), 10**9)["step"]
    logged_before = _steps_of(run, "epsilon")
    budget = stopped + 200
    resumed = subprocess.run([sys.executable, "-m", "tracelab.cli", "train", "--resume", str(run),
                              "--total-timesteps", str(budget)], capture_output=True, text=True,
                             timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert "in the same run" in resumed.stderr
    after = _steps_of(run, "epsilon")
    assert after[:len(logged_before)] == logged_before and len(set(after)) == len(after)
    new = after[len(logged_before):]
    assert new and min(new) > stopped and max(new) >= budget  # continues past the checkpoint, to the end
    assert run_rows(run, "SELECT step FROM metrics WHERE name = 'resumed'") == [(stopped,)]
    meta = run_info(run).meta
    assert meta["status"] == "finished" and meta["config"]["steps"] == budget
    assert meta["resumes"][0]["after"] == "interrupted"


def test_run_new_branches_as_before(tmp_path):
    run, branch = tmp_path / "run", tmp_path / "branch"
    cfg = walk_config(steps=480, seed=11)
    assert train_walk(cfg, run, stop_at=246) == 130
    # a branch may raise the budget too; RUN stays as it was
    assert main(["train", "--resume", str(run), *walk_argv(), "--run", str(branch), "--total-timesteps", "600"]) == 0
    assert run_info(run).status == "interrupted" and _steps_of(run, "epsilon") == [100, 200]
    assert "resumes" not in run_info(run).meta and not _steps_of(run, "resumed")
    assert _steps_of(branch, "epsilon") == [300, 400, 500, 600]
    assert run_info(branch).meta["config"]["steps"] == 600
    assert run_info(branch).meta["config"]["resumed_from"] == {"run": str(run), "step": 248}


def test_total_timesteps_raises_the_budget_of_a_finished_run(tmp_path, capsys):
    run = tmp_path / "run"
    assert train_walk(walk_config(steps=400, seed=2), run) == 0
    assert main(["train", "--resume", str(run), *walk_argv(), "--total-timesteps", "600"]) == 0
    assert _steps_of(run, "epsilon") == [100, 200, 300, 400, 500, 600]
    meta = run_info(run).meta
    assert meta["status"] == "finished" and meta["config"]["steps"] == 600
    assert [(r["step"], r["after"], r["steps"]) for r in meta["resumes"]] == [(400, "finished", 600)]
    # the old spelling is accepted too
    assert main(["train", "--resume", str(run), *walk_argv(), "--steps", "700"]) == 0
    assert _steps_of(run, "epsilon")[-1] == 700 and len(run_info(run).meta["resumes"]) == 2


def test_nothing_to_resume_and_a_budget_below_the_checkpoint_say_so(tmp_path, capsys):
    run = tmp_path / "run"
    assert train_walk(walk_config(steps=200, seed=2), run) == 0
    capsys.readouterr()
    metrics = run_rows(run, "SELECT count(*) FROM metrics")[0][0]
    line = _error_line(capsys, main(["train", "--resume", str(run), *walk_argv()]))
    assert "nothing to resume" in line and "--total-timesteps" in line and "200" in line
    line = _error_line(capsys, main(["train", "--resume", str(run), *walk_argv(), "--total-timesteps", "100"]))
    assert "--total-timesteps 100 is below the checkpoint's step 200" in line
    # nothing was written: the run is as it was
    assert run_info(run).status == "finished" and "resumes" not in run_info(run).meta
    assert run_rows(run, "SELECT count(*) FROM metrics")[0][0] == metrics
    assert not list(tmp_path.glob("run-from-*"))


def test_a_sealed_run_is_refused_with_the_way_to_branch(tmp_path, capsys):
    run = tmp_path / "run"
    cfg = walk_config(steps=480, seed=11)
    assert train_walk(cfg, run, stop_at=246) == 130
    seal_run(run)
    capsys.readouterr()
    line = _error_line(capsys, main(["train", "--resume", str(run), *walk_argv()]))
    assert "is sealed" in line and "--run NEW" in line
    assert run_info(run).status == "interrupted"
    assert main(["train", "--resume", str(run), *walk_argv(), "--run", str(tmp_path / "branch")]) == 0


def test_a_run_resumed_twice_keeps_counting(tmp_path):
    run = tmp_path / "run"
    cfg = walk_config(steps=480, seed=11)
    assert train_walk(cfg, run, stop_at=120) == 130
    source = walk_source()
    state = load_env_checkpoint(run, source, memory_limit(None, "--max-memory"))
    assert train_walk(checkpoint_config(state), run, stop_at=300, source=source, state=state, resumed_from=str(run),
                      same_run=True) == 130
    assert main(["train", "--resume", str(run), *walk_argv()]) == 0
    assert _steps_of(run, "epsilon") == [100, 200, 300, 400, 480]
    assert [v for (v,) in run_rows(run, "SELECT value FROM metrics WHERE name = 'resumed' ORDER BY step")] == \
        [1.0, 2.0]
    assert len(run_info(run).meta["resumes"]) == 2
    total, distinct = run_rows(run, "SELECT count(*), count(DISTINCT episode) FROM episodes")[0]
    assert total == distinct
