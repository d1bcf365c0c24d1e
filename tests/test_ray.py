"""Ray for experiments and sweeps (issue 30 §1): `experiment --ray` runs the trainings as Ray tasks with the
--jobs layout and figures, Ctrl-C cancels them and closes their runs; `sweep` runs a Ray Tune search whose
trials are ordinary runs, and names the best. Real Ray (a local Ray started by each command), real
trainings of a few hundred steps."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("ray")
pytest.importorskip("matplotlib")

from patience import PATIENCE, wait_until  # noqa: E402
from train_helpers import training  # noqa: E402

from tracelab.cli import main  # noqa: E402
from tracelab.store import open_run, run_info  # noqa: E402
from tracelab.train.sweep_spec import SweepSpecError, build_spec  # noqa: E402

TINY = ["--steps", "400", "--eval-games", "8", "--kernel", "counting"]
TINY_TRIAL = ["--set", "steps=600", "--set", "eval_every=300", "--set", "eval_games=10", "--set", "eval_envs=10",
              "--set", "warmup=100", "--set", "log_every=100", "--set", "envs=8", "--set", "kernel=counting",
              "--set", "checkpoint_every=0"]
ARMS = ("1v1-base-seed0", "1v1-base-the-method-s-reward-scale-seed0")


def layout(out: Path) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.parent == out or p.parent.name == "1v1-base")


def figures(out: Path) -> list:
    """What the report is built from: every seed's status, steps and final evaluations."""
    d = json.loads((out / "1v1-base.json").read_text())
    return [[(s["run"].rsplit("/", 1)[-1], s["status"], s["steps"], s["final"]) for s in a["seeds"]] for a in d["arms"]]


def test_experiment_on_ray_matches_jobs(tmp_path, capsys):
    """The same runs, report and figures as the process pool (the trainings are deterministic)."""
    on_ray, in_pool = tmp_path / "ray", tmp_path / "jobs"
    assert main(["experiment", "1v1-base", "--quick", *TINY, "--ray", "--out", str(on_ray)]) == 0
    assert f"report: {on_ray / '1v1-base.md'}" in capsys.readouterr().out
    assert main(["experiment", "1v1-base", "--quick", *TINY, "--jobs", "2", "--out", str(in_pool)]) == 0
    assert layout(on_ray) == layout(in_pool)
    assert {"1v1-base.md", "1v1-base.json", *ARMS} <= set(layout(on_ray))
    assert figures(on_ray) == figures(in_pool)
    for arm in ARMS:
        assert run_info(on_ray / arm).status == "finished"
    assert json.loads((on_ray / "1v1-base.json").read_text())["arms"][0]["seeds"][0]["run"] == str(on_ray / ARMS[0])


def test_ray_and_jobs_together_is_one_line(capsys):
    assert main(["experiment", "1v1-base", "--quick", "--ray", "--jobs", "2"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["tracelab: error: --jobs and --ray: Ray decides how many trainings run at a time; give one of them"]


def test_an_address_where_nothing_answers_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "tracelab", "experiment", "1v1-base", "--quick", "--ray",
                           "127.0.0.1:1", "--out", str(tmp_path / "exp")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    assert proc.stderr.splitlines() == ["tracelab: error: --ray 127.0.0.1:1: no Ray cluster answers there "
                                        "(Connection refused)"]


def interrupt_when_training(argv: list[str], runs: list[Path]) -> str:
    """Start `tracelab ARGV` (SIGINT as a terminal's, not ignored as a background job's), press Ctrl-C once
    every run in `runs` trains; its stderr, after checking it ended with status 130."""
    proc = subprocess.Popen([sys.executable, "-m", "tracelab", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        wait_until(lambda: training(proc, runs), f"every trial of {runs[0].parent} training", poll=0.5)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=PATIENCE)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    return err


def test_ctrl_c_cancels_the_ray_tasks_and_closes_their_runs(tmp_path):
    out = tmp_path / "exp"
    runs = [out / arm for arm in ARMS]
    err = interrupt_when_training(["experiment", "1v1-base", "--quick", "--steps", "50000000", "--kernel", "counting",
                                   "--ray", "--out", str(out)], runs)
    assert err.strip().splitlines()[-1] == f"tracelab: interrupted: no report written (the runs so far are in {out})"
    assert [run_info(r).status for r in runs] == ["interrupted", "interrupted"]


def test_ctrl_c_stops_the_sweep_and_closes_its_trials(tmp_path):
    """Evaluations far apart: the trials still stop (they report to Tune at least every 2 s)."""
    out = tmp_path / "sweep"
    runs = [out / "trial-000", out / "trial-001"]
    err = interrupt_when_training(["sweep", "--set", "steps=50000000", "--set", "eval_every=10000000", "--set",
                                   "envs=8", "--set", "kernel=counting", "--grid", "lr=1e-4,1e-3", "--out", str(out)],
                                  runs)
    assert err.strip().splitlines()[-1] == (f"tracelab: interrupted: the sweep was stopped (its trials' runs are "
                                            f"closed, in {out})")
    assert [run_info(r).status for r in runs] == ["interrupted", "interrupted"]
    assert all((r / "checkpoint").is_dir() for r in runs)


def best_metric(run: Path, name: str) -> tuple[float, int]:
    """The highest value of a metric in a run, and its first step."""
    con = open_run(run)
    try:
        return con.execute("SELECT value, step FROM metrics WHERE name = ? ORDER BY value DESC, step LIMIT 1",
                           [name]).fetchone()
    finally:
        con.close()


def test_sweep_names_the_best_trial_from_its_runs(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", *TINY_TRIAL, "--grid", "lr=1e-4,3e-3", "--metric", "eval/mean_return",
                 "--out", str(out)]) == 0
    captured = capsys.readouterr()
    trials = sorted(out.glob("trial-*"))
    assert [t.name for t in trials] == ["trial-000", "trial-001"]
    assert [run_info(t).status for t in trials] == ["finished", "finished"]
    assert sorted(run_info(t).meta["config"]["lr"] for t in trials) == [1e-4, 3e-3]
    # a GridWar sweep's trials train through its spec, as `train --scenario` does (issue 38)
    assert {run_info(t).meta["config"]["env"]["name"] for t in trials} == {"tracelab/GridWar-base-v0"}
    returns = {t: best_metric(t, "eval/mean_return") for t in trials}
    best = max(trials, key=lambda t: returns[t][0])
    line = captured.out.strip().splitlines()[-1]
    value, step = returns[best]
    assert line.startswith(f"best trial: {best}  lr=") and line.endswith(f"(eval/mean_return {value:.3f} at step "
                                                                         f"{step:,})")
    assert "Configuration for experiment" not in captured.out + captured.err  # Tune's tables: in tune.log
    assert "Configuration for experiment" in (out / "tune.log").read_text()


def test_sweep_spec_file_and_its_errors(tmp_path):
    f = tmp_path / "sweep.toml"
    f.write_text('samples = 3\nscheduler = "asha"\n[set]\nsteps = 2000\neval_every = 500\n'
                 '[grid]\nlr = [1e-4, 3e-4]\n[random]\nreward_scale = "loguniform:0.01,1"\n')
    spec = build_spec(file=str(f), grids=["batch-size=64,128"])
    assert spec.trials == 2 * 2 * 3 and spec.fixed == {"steps": 2000, "eval_every": 500}
    assert [a.describe() for a in spec.axes] == ["lr in [0.0001, 0.0003]", "batch in [64, 128]",
                                                 "reward_scale ~ loguniform[0.01, 1.0]"]
    bad = {
        ("--grid", "lrr=1e-4"): "--grid lrr=1e-4: TrainConfig has no field 'lrr' (did you mean lr?)",
        ("--grid", "lr=fast"): "--grid lr=fast: lr must be a number, got 'fast'",
        ("--grid", "lr=-1"): "--grid lr=-1: gamma must be in (0, 1] and lr > 0, got 0.99, -1.0",
        ("--random", "reward_scale=gauss:1,2"): "--random reward_scale=gauss:1,2: expected DIST:LOW,HIGH or "
                                                "choice:V1,V2 with DIST one of uniform, loguniform, randint, "
                                                "got 'gauss:1,2'",
        ("--random", "reward_scale=loguniform:0,1"): "--random reward_scale=loguniform:0,1: loguniform needs "
                                                     "bounds above 0, got 0",
        ("--random", "batch=uniform:1,2"): "--random batch=uniform:1,2: batch is an int field: use randint",
        ("--grid", "scenario=base,advanced"): "--grid scenario=base,advanced: scenario cannot be searched (one "
                                              "sweep trains one scenario; --set it)",
    }
    for (flag, value), message in bad.items():
        with pytest.raises(SweepSpecError) as e:
            build_spec(grids=[value] if flag == "--grid" else [], randoms=[value] if flag == "--random" else [])
        assert str(e.value) == message
    f.write_text('steps_per_trial = 3\n[grid]\nlr = [1e-4]\n')
    with pytest.raises(SweepSpecError, match=r"sweep.toml:1:1: steps_per_trial: unknown key"):
        build_spec(file=str(f))
    f.write_text('[grid]\nlr = [1e-4]\nlearning_rate = [3]\n')
    with pytest.raises(SweepSpecError, match=r"sweep.toml:3:1: grid.learning_rate: TrainConfig has no field "
                                             r"'learning_rate' \(did you mean learning-rate\?\)"):
        build_spec(file=str(f))
    with pytest.raises(SweepSpecError, match=r"^metric must be one of the evaluations' metrics \(eval/games, .*"
                                             r"eval/method_win_rate, eval/actions_per_win\), got 'eval/win_rat'$"):
        build_spec(grids=["lr=1e-4,3e-4"], metric="eval/win_rat")
    with pytest.raises(SweepSpecError, match=r"asha stops trials at their evaluations: it needs eval_every"):
        build_spec(grids=["lr=1e-4,3e-4"], sets=["steps=1000", "eval_every=0"], scheduler="asha")


def test_bad_sweep_is_one_line_before_ray_starts(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "tracelab", "sweep", "--grid", "lr=1e-4", "--random",
                           "gamma=uniform:0.9,1.5", "--out", str(tmp_path / "s")],
                          capture_output=True, text=True, timeout=PATIENCE)
    assert proc.returncode == 1
    assert proc.stderr.splitlines() == ["tracelab: error: --random gamma=uniform:0.9,1.5: gamma must be in (0, 1] "
                                        "and lr > 0, got 1.5, 0.0005"]
    assert not (tmp_path / "s").exists()
