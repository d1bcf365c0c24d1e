"""Several training runs side by side (issue 27 §3), on three real tiny trainings (seconds each) that
differ in their seed and learning rate: `tracelab compare RUN...`, read through the store's sandboxed
reader, and the TUI's Training view overlaying runs (`tracelab tui RUN RUN ...`) with their mean and
min–max band, driven by textual's pilot, with a snapshot (tests/data/tui_snapshots/overlay-training.txt)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from tui_helpers import run_app, wait_for
from tui_snapshot import check_snapshot

from tracelab.cli import main
from tracelab.store import open_run
from tracelab.viewers.tui.plot import BraillePlot
from train_helpers import tiny_training_run

ROOT = Path(__file__).resolve().parent.parent
PLAY_RUN = ROOT / "sample_runs" / "base"
REASONING_RUN = ROOT / "sample_runs" / "supply-chain"


@pytest.fixture(scope="module")
def three_runs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Three finished trainings of the tiny walk (400 steps: logs every 100, evaluations at 200 and 400)."""
    root = tmp_path_factory.mktemp("compare")
    return [tiny_training_run(root / f"seed{seed}", steps=400, seed=seed, lr=lr, trace_eval_games=0)
            for seed, lr in ((1, 3e-3), (2, 1e-3), (3, 3e-3))]


@pytest.fixture()
def two_runs(three_runs: list[Path]) -> list[Path]:
    return three_runs[:2]


def last_values(run: Path) -> dict[str, float]:
    con = open_run(run)
    try:
        return dict(con.execute("SELECT name, arg_max(value, step) FROM metrics GROUP BY name").fetchall())
    finally:
        con.close()


def table_rows(text: str) -> dict[str, list[str]]:
    """The text table as key -> cells (columns split on two spaces or more)."""
    import re
    lines = text.splitlines()
    return {cells[0]: cells[1:] for cells in (re.split(r"\s{2,}", ln.strip()) for ln in lines[2:-1])}


def test_compare_prints_final_metrics_and_only_the_config_keys_that_differ(two_runs, capsys):
    a, b = two_runs
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    header = out.splitlines()[0].split()
    assert header == ["key", str(a), str(b)]                      # runs named by their paths
    rows = table_rows(out)
    assert rows["status"] == ["finished", "finished"] and rows["last step"] == ["400", "400"]
    config_rows = {k for k in rows if k.startswith("config ")}
    assert config_rows == {"config lr", "config seed"}            # batch, scenario, ... are the same
    assert rows["config lr"] == ["0.003", "0.001"] and rows["config seed"] == ["1", "2"]
    for run, column in ((a, 0), (b, 1)):
        final = last_values(run)
        assert float(rows["eval/win_rate"][column]) == pytest.approx(final["eval/win_rate"], abs=5e-4)
        assert float(rows["loss"][column]) == pytest.approx(final["loss"], rel=1e-3)
        assert rows["eval/games"][column] == "8"
        best, at = rows["eval/win_rate (best)"][column].split(" @")
        assert int(at) in (200, 400)


def test_compare_as_json_keeps_full_precision(two_runs, capsys):
    a, b = two_runs
    assert main(["compare", str(a), str(b), "--format", "json"]) == 0
    rows = {r["key"]: r for r in json.loads(capsys.readouterr().out)}
    assert float(rows["loss"][str(a)]) == last_values(a)["loss"]


@pytest.mark.parametrize("other, says", [
    (PLAY_RUN, "is a play run (games, no training metrics): compare puts training runs side by side"),
    (REASONING_RUN, "is a reasoning run (a trace, no training metrics)"),
])
def test_compare_refuses_a_run_that_is_not_a_training_run_in_one_line(two_runs, capsys, other, says):
    assert main(["compare", str(two_runs[0]), str(other)]) == 1
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith(f"tracelab: error: {str(other)!r} {says}") and "\n" not in err
    assert "tracelab diff RUN_A RUN_B" in err and captured.out == ""


def test_compare_names_an_unknown_or_broken_run_in_one_line(two_runs, tmp_path, capsys):
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "meta.json").write_text("{")
    for bad, says in ((tmp_path / "nope", "no run"), (tmp_path / "broken", "meta.json:")):
        assert main(["compare", str(two_runs[0]), str(bad)]) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("tracelab: error: ") and says in err and str(bad.name) in err and "\n" not in err
    assert main(["compare", str(two_runs[0]), str(two_runs[0])]) == 1
    assert "is given twice" in capsys.readouterr().err


def curve(run: Path, name: str) -> tuple[list[int], list[float]]:
    con = open_run(run)
    try:
        rows = con.execute("SELECT step, value FROM metrics WHERE name = ? ORDER BY step", [name]).fetchall()
    finally:
        con.close()
    return [s for s, _ in rows], [v for _, v in rows]


def test_mean_band_matches_runs_at_each_step_by_their_latest_value():
    from tracelab.viewers.tui.run_overlay import mean_band
    a = ([100, 200, 300], [1.0, 2.0, 3.0])
    b = ([150, 250, 350], [10.0, 20.0, 30.0])        # logs at other steps
    steps, mean, low, high = mean_band([a, b])
    assert steps == [150, 200, 250, 300]             # from the last first step to the first last step
    assert low == [1.0, 2.0, 2.0, 3.0] and high == [10.0, 10.0, 20.0, 20.0]
    assert mean == [5.5, 6.0, 11.0, 11.5]
    c = ([100, 200], [float("nan"), 4.0])
    steps, mean, low, high = mean_band([a, c])
    assert mean[0] == 1.0 and low[1] == 2.0 and high[1] == 4.0  # a NaN value is left out
    assert mean_band([a]) is None and mean_band([a, ([500], [1.0])]) is None


def test_tui_overlays_runs_in_the_training_view_with_their_mean_and_band(three_runs, monkeypatch):
    monkeypatch.chdir(three_runs[0].parent)   # runs named by relative paths: the snapshot shows no tmp dir
    failures: list[str] = []

    async def body(app: Any, pilot: Any) -> None:
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        pane = app.screen.panes["training"]
        await wait_for(pilot, lambda: pane.is_attached and pane.updates > 0
                       and not any(w.is_running for w in app.workers))
        title = app.screen.query_one("#title").render().plain
        assert title.startswith(" seed1 + 2 overlaid in Training")
        loss = app.screen.query_one("#plot-loss", BraillePlot)
        assert [s.name for s in loss.series] == ["loss mean"] and len(loss.bands) == 1
        curves = [curve(run, "loss") for run in three_runs]
        assert all(steps == [100, 200, 300, 400] for steps, _ in curves)   # the runs log at the same steps
        band, mean = loss.bands[0], loss.series[0]
        assert band.xs == mean.xs == [100, 200, 300, 400]
        for i in range(4):
            at = [values[i] for _, values in curves]
            assert mean.ys[i] == pytest.approx(sum(at) / 3)
            assert (band.lows[i], band.highs[i]) == (min(at), max(at))
        status = app.screen.query_one("#train-status").render().plain
        assert status.strip() == "3 runs: seed1, seed2, seed3 · line: their mean, shade: min–max · m: each run"
        await pilot.pause(0.2)
        diff = check_snapshot("overlay-training", app)
        if diff:
            failures.append(diff)
        await pilot.press("m")                                         # one curve per run
        assert [s.name for s in loss.series] == ["seed1: loss", "seed2: loss", "seed3: loss"]
        assert loss.bands == [] and [s.ys for s in loss.series] == [values for _, values in curves]
        assert "one curve per run" in app.screen.query_one("#train-status").render().plain
        await pilot.press("escape")                                    # back: the Runs screen lists the three
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunsScreen")

    run_app([Path(r.name) for r in three_runs], body, size=(100, 30))
    if failures:
        pytest.fail("\n".join(failures), pytrace=False)


def test_one_run_has_no_overlay_key(three_runs):
    async def body(app: Any, pilot: Any) -> None:
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        await pilot.press("6")
        pane = app.screen.panes["training"]
        await wait_for(pilot, lambda: pane.is_attached and pane.updates > 0)
        loss = app.screen.query_one("#plot-loss", BraillePlot)
        assert [s.name for s in loss.series] == ["loss"] and loss.bands == []
        assert "each run" not in app.screen.query_one("KeyBar").render().plain
    run_app([three_runs[0]], body, size=(100, 30))


def test_experiment_win_rate_plot_draws_the_seeds_mean_and_band_from_real_runs(three_runs, tmp_path):
    """The plot `tracelab experiment` makes, drawn from three real runs' curves as its report reads them."""
    pytest.importorskip("matplotlib")
    from PIL import Image

    from tracelab.train.experiments.plots import draw_learning_curves, learning_curves
    from tracelab.train.experiments.runner import curves
    seeds = [(k + 1, *curves(run, ("eval/method_win_rate",))["eval/method_win_rate"])
             for k, run in enumerate(three_runs)]
    arms = [{"label": "walk4", "published": None, "seeds": seeds}]
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    draw_learning_curves(ax, arms, ylabel="win rate (%)", title="walk4", percent=True, small=True)
    lines = {line.get_label(): line for line in ax.get_lines()}
    mean = lines["walk4, mean of 3 seeds"]
    assert list(mean.get_xdata()) == [200, 400]
    for j, step in enumerate((200, 400)):
        at = [curve(run, "eval/method_win_rate")[1][j] for run in three_runs]
        assert mean.get_ydata()[j] == pytest.approx(100 * sum(at) / 3)
    band = ax.collections[0].get_paths()[0].vertices            # the 95% interval, around the mean
    for j, step in enumerate((200, 400)):
        ys = band[band[:, 0] == step][:, 1]
        assert ys.min() <= mean.get_ydata()[j] <= ys.max() and ys.min() >= 0 and ys.max() <= 100
    assert [f"walk4, seed {k}" in lines for k in (1, 2, 3)] == [True] * 3   # each seed's line too
    plt.close(fig)
    png = learning_curves(tmp_path / "win_rate.png", arms, metric="eval/method_win_rate",
                          ylabel="win rate (%)", title="walk4", percent=True, small=True)
    with Image.open(png) as im:
        assert im.format == "PNG" and im.size == (640, 340)


def test_runs_screen_marks_runs_and_opens_them_overlaid(three_runs):
    async def body(app: Any, pilot: Any) -> None:
        from tui_helpers import loaded
        screen = app.screen
        table = screen.query_one("#runs-table")
        await wait_for(pilot, lambda: loaded(table) and table.count == 3)
        await pilot.press("c")                                          # nothing marked: says how
        await wait_for(pilot, lambda: any("mark two runs or more" in n.message for n in app._notifications))
        table.move_to([table.row(i)["name"] for i in range(3)].index("seed2"))
        await pilot.press("space")                                      # marks seed2, moves down
        table.move_to([table.row(i)["name"] for i in range(3)].index("seed1"))
        await pilot.press("space")
        assert screen.marked == [str(three_runs[1]), str(three_runs[0])]
        assert "2 marked, c compares them" in screen.query_one("#runs-status").render().plain
        await pilot.press("c")
        await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
        assert app.screen.query_one("#title").render().plain.startswith(" seed2 + 1 overlaid in Training")
        pane = app.screen.panes["training"]
        await wait_for(pilot, lambda: pane.is_attached and pane.updates > 0)
        assert [r.label for r in pane.runs] == ["seed2", "seed1"]
        assert [s.name for s in app.screen.query_one("#plot-loss", BraillePlot).series] == ["loss mean"]
    run_app([three_runs[0].parent], body, size=(120, 30))


def test_overlaid_live_runs_grow_together(tmp_path):
    """Two runs written by other processes while the overlay is shown: the mean and band follow both."""
    from tui_helpers import live_writer
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    with live_writer("train", tmp_path / "a") as (run_a, _), live_writer("train", tmp_path / "b") as (run_b, _):
        async def body(app: Any, pilot: Any) -> None:
            await wait_for(pilot, lambda: type(app.screen).__name__ == "RunScreen")
            loss = app.screen.query_one("#plot-loss", BraillePlot)
            await wait_for(pilot, lambda: len(loss.bands) == 1 and len(loss.bands[0].xs) > 0)
            first = loss.bands[0].xs[-1]
            await wait_for(pilot, lambda: loss.bands[0].xs[-1] >= first + 300)   # both runs went on
            assert loss.series[0].name == "loss mean" and loss.series[0].xs == loss.bands[0].xs
            assert "2 runs: " in app.screen.query_one("#train-status").render().plain
        run_app([run_a, run_b], body, size=(100, 30))
