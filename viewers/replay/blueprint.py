"""The replay's layout: the board, the rule log and the plots side by side; the why document and the
state lanes underneath; the time panel on the `step` timeline."""
from __future__ import annotations

import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn, TextLogColumnKind
from tracelab.viewers.replay import style

from tracelab.viewers.board import BoardMap


def replay_blueprint(board_map: BoardMap, training: bool = False, open_at: str = "start") -> rrb.Blueprint:
    """open_at: where the time cursor starts, "start" (paused at step 0) or "end" (following: the last
    step)."""
    plots: list[rrb.View] = [rrb.TimeSeriesView(origin=style.PLOTS, name="Reward and return")]
    if training:
        plots.append(rrb.TimeSeriesView(origin=style.TRAIN, name="Training"))
    board = rrb.Spatial2DView(
        origin=style.BOARD, name="Board", background=(24, 24, 28),
        visual_bounds=rrb.VisualBounds2D(x_range=[-0.2, board_map.width + 0.2],
                                         y_range=[-0.2, board_map.height + 0.2]))
    rule_log = rrb.TextLogView(
        origin=style.RULE_LOG, name="Fired rules (level = phase)",
        columns=rrb.TextLogColumns(text_log_columns=[TextLogColumn(TextLogColumnKind.LogLevel),
                                                     TextLogColumn(TextLogColumnKind.Body)]))
    top = rrb.Horizontal(board, rule_log, rrb.Vertical(*plots), column_shares=[4, 5, 3])
    bottom = rrb.Horizontal(rrb.TextDocumentView(origin=style.WHY, name="Why"),
                            rrb.StateTimelineView(origin=style.LANES, name="State lanes"),
                            column_shares=[3, 2])
    return rrb.Blueprint(rrb.Vertical(top, bottom, row_shares=[3, 2]),
                         rrb.TimePanel(timeline=style.STEP, state="collapsed",
                                       play_state="following" if open_at == "end" else "paused"),
                         rrb.BlueprintPanel(state="hidden"), rrb.SelectionPanel(state="hidden"))
