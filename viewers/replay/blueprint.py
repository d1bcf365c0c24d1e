"""The replay's layout: the board, the rule log and the plots side by side; the why document and the
state lanes underneath; the time panel on the `step` timeline.

The plots and the lanes span the steps with a margin past the last one: fitted to the data, the last
step sat on the right edge, where a game's final jump in reward (a kill, a capture) was cut off."""
from __future__ import annotations

import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn, TextLogColumnKind
from tracelab.viewers.replay import style

from tracelab.board import Board
from tracelab.viewers.replay.board_layer import visual_bounds

STEP_MARGIN = 0.06      # of the steps (at least 2), past the last one on the plots' and lanes' axes


def step_axis(last_step: int) -> rrb.archetypes.TimeAxis:
    """The `step` axis from 0 to a little past `last_step` (at least two steps), so the last step shows."""
    end = last_step + max(2, round(last_step * STEP_MARGIN))
    return rrb.archetypes.TimeAxis(view_range=rr.TimeRange(start=rr.TimeRangeBoundary.absolute(seq=0),
                                                           end=rr.TimeRangeBoundary.absolute(seq=end)))


def agent_views(last_step: int, values: bool, terms: bool) -> list[rrb.View]:
    """The plots of the agent's half (agent_plots.py), for a run that records decisions and reward terms."""
    return ([rrb.TimeSeriesView(origin=style.VALUES, name="Action values", axis_x=step_axis(last_step))]
            if values else []) + \
        ([rrb.TimeSeriesView(origin=style.TERMS, name="Return by term (stacked)", axis_x=step_axis(last_step))]
         if terms else [])


def replay_blueprint(board: Board | None, training: bool = False, open_at: str = "start",
                     last_step: int = 0, values: bool = False, terms: bool = False) -> rrb.Blueprint:
    """open_at: where the time cursor starts, "start" (paused at step 0) or "end" (following: the last
    step). last_step: the longest episode's last step, where the plots' and lanes' axes end. values,
    terms: the run records decisions, reward terms (their plots under the reward's)."""
    plots: list[rrb.View] = [rrb.TimeSeriesView(origin=style.PLOTS, name="Reward and return",
                                                axis_x=step_axis(last_step)),
                             *agent_views(last_step, values, terms)]
    if training:
        plots.append(rrb.TimeSeriesView(origin=style.TRAIN, name="Training"))
    board_view = rrb.Spatial2DView(origin=style.BOARD, name="Board", background=(24, 24, 28),
                                   visual_bounds=None if board is None else visual_bounds(board))
    rule_log = rrb.TextLogView(
        origin=style.RULE_LOG, name="Fired rules (level = phase)",
        columns=rrb.TextLogColumns(text_log_columns=[TextLogColumn(TextLogColumnKind.LogLevel),
                                                     TextLogColumn(TextLogColumnKind.Body)]))
    top = rrb.Horizontal(board_view, rule_log, rrb.Vertical(*plots), column_shares=[4, 5, 3])
    bottom = rrb.Horizontal(rrb.TextDocumentView(origin=style.WHY, name="Why"),
                            rrb.StateTimelineView(origin=style.LANES, name="State lanes",
                                                  time_view=step_axis(last_step)),
                            column_shares=[3, 2])
    return rrb.Blueprint(rrb.Vertical(top, bottom, row_shares=[3, 2]),
                         rrb.TimePanel(timeline=style.STEP, state="collapsed",
                                       play_state="following" if open_at == "end" else "paused"),
                         rrb.BlueprintPanel(state="hidden"), rrb.SelectionPanel(state="hidden"))
