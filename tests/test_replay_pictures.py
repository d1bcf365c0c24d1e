"""What the replay's pictures showed wrong, read back from the saved .rrd (its blueprint): the plots and the
lanes ended on the last step (the final jump cut off at the right edge), a base in the bottom row had its
label cut off."""
from __future__ import annotations

from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from tracelab.cli import main
from tracelab.store.reader import open_run

SAMPLES = Path(__file__).resolve().parent.parent / "sample_runs"
SKIP = {"rerun.controls.RowId", "blueprint", "log_time"}


def blueprint_views(path: Path) -> dict[str, dict[str, object]]:
    """View name -> its blueprint components (component column -> first value), from the .rrd's blueprint."""
    reader = RrdReader(path)
    by_entity: dict[str, dict[str, object]] = {}
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            row = by_entity.setdefault(chunk.entity_path, {})
            for name in batch.schema.names:
                if name not in SKIP:
                    row[name] = batch.column(name).to_pylist()[0][0]
    views = {}
    for entity, row in by_entity.items():
        if "ViewBlueprint:display_name" in row:
            parts = {k: v for e, r in by_entity.items() if e.startswith(entity + "/") for k, v in r.items()}
            views[str(row["ViewBlueprint:display_name"])] = row | parts
    return views


def steps_of(run: Path, episodes: str) -> list[int]:
    con = open_run(run)
    try:
        lo, _, hi = episodes.partition("-")
        return [s for (s,) in con.execute("SELECT steps FROM episodes WHERE episode BETWEEN ? AND ?",
                                          [int(lo), int(hi or lo)]).fetchall()]
    finally:
        con.close()


@pytest.fixture(scope="module")
def saved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("replay-pictures") / "advanced.rrd"
    assert main(["replay", str(SAMPLES / "advanced"), "--episodes", "0-2", "--open-at", "end",
                 "--save", str(path)]) == 0
    return path


def test_the_plots_and_the_lanes_reach_past_the_longest_games_last_step(saved: Path) -> None:
    longest = max(steps_of(SAMPLES / "advanced", "0-2"))
    views = blueprint_views(saved)
    for name in ("Reward and return", "State lanes"):
        axis = views[name].get("TimeAxis:view_range")
        assert axis is not None, f"{name}: no step axis in the blueprint (fitted to the data)"
        assert axis["start"] == 0 and axis["end"] > longest, (name, axis, longest)


def test_the_board_leaves_room_under_the_bottom_row_for_a_base_label(saved: Path) -> None:
    bounds = blueprint_views(saved)["Board"]["VisualBounds2D:range"]
    assert bounds["y_range"][1] >= 8 + 0.5  # the advanced board is 8 rows; the red base is in the bottom one
    assert bounds["x_range"][0] < 0 and bounds["x_range"][1] > 8   # both edges of its 8 columns in view


def test_every_view_of_a_training_runs_replay_has_data_on_the_step_timeline(tmp_path: Path) -> None:
    """sample_runs/base-train's first traced evaluation game (docs/images/replay-values.png): no view of the
    blueprint stands empty under the time panel's `step` timeline (its Training panel did: the metrics
    were on `train_step`, which rerun does not plot while `step` is the active timeline)."""
    con = open_run(SAMPLES / "base-train")
    try:
        episode = con.execute("SELECT min(episode) FROM episodes WHERE kind = 'eval'").fetchall()[0][0]
    finally:
        con.close()
    path = tmp_path / "values.rrd"
    assert main(["replay", str(SAMPLES / "base-train"), "--episode", str(episode), "--save", str(path)]) == 0
    reader = RrdReader(path)
    on_step: set[str] = set()
    for store in reader.recordings():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            if "step" in batch.schema.names or chunk.is_static:
                on_step.add(chunk.entity_path)
    views = blueprint_views(path)
    assert "Training" not in views
    for name, view in views.items():
        origin = str(view.get("ViewBlueprint:space_origin"))
        assert any(p == origin or p.startswith(origin.rstrip("/") + "/") for p in on_step), (name, origin)
