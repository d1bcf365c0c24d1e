"""The replay's layout, every run's: the board (a run whose world declares one) or the graph on the left,
the plots under it (rewards and returns, the agent's values and terms); on the
right the rule log, the step document, the atoms changed per step and the state lanes; the time panel on
the `step` timeline.

The plots and the lanes span the steps with a margin past the last one: fitted to the data, the last
step sat on the right edge, where a game's final jump in reward (a kill, a capture) was cut off."""
from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn, TextLogColumnKind
from tracelab.viewers.replay import style

from tracelab.board import Board
from tracelab.viewers.replay.board_layer import visual_bounds

STEP_MARGIN = 0.06      # of the steps (at least 2), past the last one on the plots' and lanes' axes
GRAPH_MARGIN = 0.04     # of the drawing's size, around the nodes in the graph view's bounds


def step_axis(last_step: int) -> rrb.archetypes.TimeAxis:
    """The `step` axis from 0 to a little past `last_step` (at least two steps), so the last step shows."""
    end = last_step + max(2, round(last_step * STEP_MARGIN))
    return rrb.archetypes.TimeAxis(view_range=rr.TimeRange(start=rr.TimeRangeBoundary.absolute(seq=0),
                                                           end=rr.TimeRangeBoundary.absolute(seq=end)))


def board_view(board: Board) -> rrb.View:
    return rrb.Spatial2DView(origin=style.BOARD, name="Board", background=style.BOARD_BACKGROUND,
                             visual_bounds=visual_bounds(board))


def color_legend(label: str | None) -> str:
    if label is None:
        return "Graph (no predicate over nodes to colour them by)"
    return f"Graph: {label} (grey [0,1] unknown, blue [0,0] false, red [1,1] true)"


def graph_view(positions: np.ndarray, color_label: str | None) -> rrb.View:
    """The graph's view: its bounds fit the nodes, its force simulation off (every node has its position)."""
    lo, hi = (positions.min(axis=0), positions.max(axis=0)) if len(positions) else (np.zeros(2), np.ones(2))
    pad = float((hi - lo).max()) * GRAPH_MARGIN + style.NODE_RADIUS * 2
    return rrb.GraphView(
        origin=style.GRAPH, name=color_legend(color_label),
        background=rrb.archetypes.GraphBackground(color=style.GRAPH_BACKGROUND),
        visual_bounds=rrb.VisualBounds2D(x_range=[float(lo[0]) - pad, float(hi[0]) + pad],
                                         y_range=[float(lo[1]) - pad, float(hi[1]) + pad]),
        force_link=rrb.archetypes.ForceLink(enabled=False),
        force_many_body=rrb.archetypes.ForceManyBody(enabled=False),
        force_position=rrb.archetypes.ForcePosition(enabled=False),
        force_collision_radius=rrb.archetypes.ForceCollisionRadius(enabled=False),
        force_center=rrb.archetypes.ForceCenter(enabled=False))


def agent_views(last_step: int, values: bool, terms: bool) -> list[rrb.View]:
    """The plots of the agent's half (agent_plots.py), for a run that records decisions and reward terms."""
    return ([rrb.TimeSeriesView(origin=style.VALUES, name="Action values", axis_x=step_axis(last_step))]
            if values else []) + \
        ([rrb.TimeSeriesView(origin=style.TERMS, name="Return by term (stacked)", axis_x=step_axis(last_step))]
         if terms else [])


def replay_blueprint(main: rrb.View, open_at: str = "start", last_step: int = 0, rewards: bool = False,
                     values: bool = False, terms: bool = False, lanes: bool = False) -> rrb.Blueprint:
    """`main`: the board's or the graph's view. open_at: where the time cursor starts, "start" (paused at
    step 0) or "end" (following: the last step). last_step: the longest episode's last step, where the
    plots' and lanes' axes end. The other flags: which plots and views the run has data for."""
    plots: list[rrb.View] = ([rrb.TimeSeriesView(origin=style.PLOTS, name="Reward and return",
                                                 axis_x=step_axis(last_step),
                                                 contents=[f"+ {style.PLOTS}/reward/**", f"+ {style.PLOTS}/return/**"])]
                             if rewards else []) + agent_views(last_step, values, terms)
    left: rrb.View | rrb.Container = rrb.Vertical(main, rrb.Horizontal(*plots), row_shares=[3, 2]) if plots else main
    rule_log = rrb.TextLogView(
        origin=style.RULE_LOG, name="Fired rules (level = rule)",
        columns=rrb.TextLogColumns(text_log_columns=[TextLogColumn(TextLogColumnKind.LogLevel),
                                                     TextLogColumn(TextLogColumnKind.Body)]))
    side: list[rrb.View] = [rule_log, rrb.TextDocumentView(origin=style.WHY, name="Step and why"),
                            rrb.TimeSeriesView(origin=style.CHANGED, name="Atoms changed per step",
                                               axis_x=step_axis(last_step),
                                               plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop))]
    shares = [2, 4, 2]      # the why-trees are the longest text
    if lanes:
        side.append(rrb.StateTimelineView(origin=style.LANES, name="State lanes", time_view=step_axis(last_step)))
        shares.append(2)
    return rrb.Blueprint(rrb.Horizontal(left, rrb.Vertical(*side, row_shares=shares), column_shares=[3, 2]),
                         rrb.TimePanel(timeline=style.STEP, state="collapsed",
                                       play_state="following" if open_at == "end" else "paused"),
                         rrb.BlueprintPanel(state="hidden"), rrb.SelectionPanel(state="hidden"))
