"""The evaluations' wall time in a training (issue 31 part 1): each evaluation's seconds, those of its traced
and untraced games, and the evaluations' share of the training's wall time are metrics of the run (so
`tracelab compare`, the TUI and reports read them as any other), and train's summary says them."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tracelab.cli import main
from tracelab.train.metric_log import EVAL_PART_SECONDS, EVAL_SECONDS, EVAL_WALL_SHARE, MetricLog

from train_helpers import run_rows

STEPS, EVAL_EVERY = 600, 200


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A short real `tracelab train` of the 1v1 base game, three evaluations, two games of each traced."""
    run = tmp_path_factory.mktemp("evaltime") / "run"
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["train", "--scenario", "base", "--total-timesteps", str(STEPS), "--num-envs", "4",
                     "--learning-starts", "100", "--batch-size", "32", "--buffer-size", "2000",
                     "--eval-every", str(EVAL_EVERY), "--eval-games", "6", "--trace-eval-games", "2",
                     "--eval-envs", "4", "--log-every", "100", "--checkpoint-every", "0", "--run", str(run)])
    assert code == 0
    return run, out.getvalue()


def test_each_evaluation_logs_its_seconds_and_the_evaluations_share_of_wall_time(trained) -> None:
    run, _ = trained
    rows = run_rows(run, f"SELECT name, step, value FROM metrics WHERE name IN "
                         f"{(EVAL_SECONDS, EVAL_WALL_SHARE, *EVAL_PART_SECONDS.values())} ORDER BY step, name")
    by_name: dict[str, list[tuple[int, float]]] = {}
    for name, step, value in rows:
        by_name.setdefault(name, []).append((step, value))
    evals = [s for (s,) in run_rows(run, "SELECT step FROM metrics WHERE name = 'eval/games' ORDER BY step")]
    assert evals == [200, 400, 600]
    for name in (EVAL_SECONDS, EVAL_WALL_SHARE, *EVAL_PART_SECONDS.values()):
        assert [s for s, _ in by_name[name]] == evals, name   # one row per evaluation, at its step
    assert all(0.0 < v < 1.0 for _, v in by_name[EVAL_WALL_SHARE])
    for (_, total), (_, traced), (_, untraced) in zip(by_name[EVAL_SECONDS], by_name["eval/traced_seconds"],
                                                      by_name["eval/untraced_seconds"]):
        assert 0.0 < traced and 0.0 < untraced and traced + untraced <= total


def test_the_summary_says_the_evaluations_share_of_the_training(trained) -> None:
    run, out = trained
    line = next(s for s in out.splitlines() if s.startswith("evaluations: "))
    m = re.fullmatch(r"evaluations: 3 in ([\d.]+) s, ([\d.]+)% of the training's ([\d.]+) s "
                     r"\(traced games ([\d.]+) s, untraced games ([\d.]+) s\)", line)
    assert m, line
    seconds, percent, training = float(m[1]), float(m[2]), float(m[3])
    assert 0 < seconds <= training and 0 < percent < 100
    last_share = run_rows(run, f"SELECT arg_max(value, step) FROM metrics WHERE name = '{EVAL_WALL_SHARE}'")[0][0]
    assert percent == pytest.approx(100 * seconds / training, rel=0.1)   # from the rounded seconds
    assert percent / 100 <= last_share + 0.05   # the share once training ended: the last evaluation's or below


def test_the_share_counts_only_the_time_inside_the_training_loop() -> None:
    log = MetricLog(None)
    assert log.eval_share() is None            # no loop yet: no share
    log.loop_started()
    log.loop_stopped()
    before = log.loop_seconds()
    m = log.evaluation_timed(0.0, {"traced": 0.0})
    assert set(m) == {EVAL_SECONDS, EVAL_WALL_SHARE, EVAL_PART_SECONDS["traced"]}
    assert log.loop_seconds() == before        # time outside the loop is not the training's


def test_compare_shows_the_share_beside_the_other_final_metrics(trained, capsys) -> None:
    run, _ = trained
    assert main(["compare", str(run), "--format", "csv"]) == 0
    rows = dict(line.split(",", 1) for line in capsys.readouterr().out.splitlines())
    share = run_rows(run, f"SELECT arg_max(value, step) FROM metrics WHERE name = '{EVAL_WALL_SHARE}'")[0][0]
    assert float(rows[EVAL_WALL_SHARE]) == pytest.approx(share)
