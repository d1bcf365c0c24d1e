"""One episode of a run without a board (a reasoning run) as one rerun recording: the graph, the fired
rules, the changes per step, the why documents and the blueprint (docs/replay.md, "A run without a
board")."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn, TextLogColumnKind
from tracelab.viewers.replay import agent_plots, board_layer, graph_layer, graph_rules, plots, style
from tracelab.viewers.replay.blueprint import agent_views, step_axis
from tracelab.viewers.replay.graph_layout import fit_given, layout
from tracelab.viewers.replay.graph_run import GraphEpisode, RunGraph, read_episode
from tracelab.viewers.replay.recording import ReplayOptions

from tracelab.board import Board, board_of_config
from tracelab.store.kind import run_config
from tracelab.store.model import RunModel
from tracelab.store.reader import RunConnection

GRAPH_MARGIN = 0.04      # of the drawing's size, around the nodes in the graph view's bounds


@dataclass
class GraphRunContext:
    """What every episode of a run without a board shares: its graph, the nodes' positions (the graph's
    own `x`/`y`, else a layout computed once) and its program model (for the why-trees)."""
    con: RunConnection
    name: str
    graph: RunGraph
    board: Board | None = None      # a spec world's board, drawn instead of the graph
    _positions: np.ndarray | None = None
    _model: RunModel | None = None
    _color_label: tuple[str | None] | None = None   # decided at the first episode, kept for the others

    @classmethod
    def of(cls, con: RunConnection, name: str) -> GraphRunContext:
        return cls(con, name, RunGraph.read(con), board_of_config(run_config(con)))

    def positions(self, episode: int) -> np.ndarray:
        """[nodes, 2] float32 drawing positions, decided at the first episode replayed."""
        if self._positions is None:
            given = self.graph.given_positions(self.con, episode)
            if given is not None:
                drawn = fit_given(given)
            else:
                drawn = layout(len(self.graph.nodes), np.concatenate([self.graph.edges, self._binary_pairs()]))
            self._positions = drawn.astype(np.float32)
        return self._positions

    def _binary_pairs(self) -> np.ndarray:
        """Node pairs of the run's binary atoms: what pulls nodes together in a layout when the run has
        no graph file's edges (facts written in a program)."""
        cols = self.con.execute("SELECT DISTINCT arg0, arg1 FROM raw.atoms WHERE arg0 >= 0 AND arg1 >= 0 "
                                "AND arg0 <> arg1").fetchnumpy()
        return np.stack([np.asarray(cols["arg0"], np.int64), np.asarray(cols["arg1"], np.int64)], axis=1)

    def color_label(self, wanted: str | None, episode: int) -> str | None:
        """--color-by, or the default of the first episode replayed (every recording colours alike)."""
        if self._color_label is None:
            self._color_label = (self.graph.color_label(self.con, wanted, episode),)
        return self._color_label[0]

    @property
    def model(self) -> RunModel:
        if self._model is None:
            self._model = RunModel(self.con)
        return self._model

    def check(self, options: ReplayOptions, episode: int) -> None:
        """The user's names before anything is drawn: --color-by and --why (one-line errors)."""
        self.color_label(options.color_by, episode)
        graph_rules.check_atoms(self.model, options.why_atoms)

    def prefetch(self, episodes: list[int]) -> None:
        """Nothing: an episode of a reasoning is read when it is recorded (its rows may be millions)."""

    def refresh(self) -> None:
        """Nothing: a reasoning run has no metrics to catch up with."""

    def record(self, episode: int, rec: rr.RecordingStream, options: ReplayOptions, blueprint: bool = True,
               last_step: int = 0) -> GraphEpisode:
        return record_graph_episode(self, episode, rec, options, blueprint, last_step)


def color_legend(label: str | None) -> str:
    if label is None:
        return "Graph (no predicate over nodes to colour them by)"
    return f"Graph: {label} (grey [0,1] unknown, blue [0,0] false, red [1,1] true)"


def graph_blueprint(positions: np.ndarray, color_label: str | None, open_at: str = "start",
                    last_step: int = 0, board: Board | None = None, rewards: bool = False,
                    values: bool = False, terms: bool = False) -> rrb.Blueprint:
    """The graph (or the board) beside the rule log, the why document and the changes per step, the
    rewards and returns under it when there are some; the graph view's bounds fit the nodes, and its
    force simulation is off (every node has its position)."""
    lo, hi = (positions.min(axis=0), positions.max(axis=0)) if len(positions) else (np.zeros(2), np.ones(2))
    pad = float((hi - lo).max()) * GRAPH_MARGIN + style.NODE_RADIUS * 2
    graph = rrb.GraphView(
        origin=style.GRAPH, name=color_legend(color_label),
        background=rrb.archetypes.GraphBackground(color=style.GRAPH_BACKGROUND),
        visual_bounds=rrb.VisualBounds2D(x_range=[float(lo[0]) - pad, float(hi[0]) + pad],
                                         y_range=[float(lo[1]) - pad, float(hi[1]) + pad]),
        force_link=rrb.archetypes.ForceLink(enabled=False),
        force_many_body=rrb.archetypes.ForceManyBody(enabled=False),
        force_position=rrb.archetypes.ForcePosition(enabled=False),
        force_collision_radius=rrb.archetypes.ForceCollisionRadius(enabled=False),
        force_center=rrb.archetypes.ForceCenter(enabled=False))
    rule_log = rrb.TextLogView(
        origin=style.RULE_LOG, name="Fired rules (level = rule)",
        columns=rrb.TextLogColumns(text_log_columns=[TextLogColumn(TextLogColumnKind.LogLevel),
                                                     TextLogColumn(TextLogColumnKind.Body)]))
    if board is not None:
        graph = rrb.Spatial2DView(origin=style.BOARD, name="Board", background=(24, 24, 28),
                                  visual_bounds=board_layer.visual_bounds(board))
    if rewards:
        plot = rrb.TimeSeriesView(origin=style.PLOTS, name="Reward and return", axis_x=step_axis(last_step),
                                  contents=[f"+ {style.PLOTS}/reward/**", f"+ {style.PLOTS}/return/**"])
        agent = agent_views(last_step, values, terms)
        graph = rrb.Vertical(graph, rrb.Horizontal(plot, *agent) if agent else plot, row_shares=[3, 2])
    side = rrb.Vertical(rule_log,
                        rrb.TextDocumentView(origin=style.WHY, name="Step and why"),
                        rrb.TimeSeriesView(origin=style.CHANGED, name="Atoms changed per step",
                                           axis_x=step_axis(last_step),
                                           plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop)),
                        row_shares=[2, 4, 2])     # the why-trees are the longest text
    return rrb.Blueprint(rrb.Horizontal(graph, side, column_shares=[3, 2]),
                         rrb.TimePanel(timeline=style.STEP, state="collapsed",
                                       play_state="following" if open_at == "end" else "paused"),
                         rrb.BlueprintPanel(state="hidden"), rrb.SelectionPanel(state="hidden"))


def record_graph_episode(ctx: GraphRunContext, episode: int, rec: rr.RecordingStream,
                         options: ReplayOptions | None = None, blueprint: bool = True,
                         last_step: int = 0) -> GraphEpisode:
    """Log one episode of a run without a board into `rec` (which already has its sink)."""
    options = options or ReplayOptions()
    data = read_episode(ctx.con, ctx.graph, episode, ctx.color_label(options.color_by, episode))
    positions = ctx.positions(episode)
    rec.send_recording_name(f"{ctx.name} episode {episode} ({data.outcome or 'running'}, {data.steps} steps)")
    rows = plots.step_rewards(ctx.con, [episode]).get(episode, [])
    agent = agent_plots.read_series(ctx.con, episode)
    if blueprint:
        rec.send_blueprint(graph_blueprint(positions, data.color_label, options.open_at,
                                           max(last_step, data.steps - 1), ctx.board, bool(rows),
                                           bool(agent.values), bool(agent.terms)))
    drawn = graph_layer.log_graph(rec, ctx.graph, positions, data)
    if ctx.board is not None:
        board_layer.log_board(rec, ctx.con, ctx.board, episode)
    if rows:
        agents = list(dict.fromkeys(agent for _, agent, _ in rows))
        plots.log_rewards(rec, plots.agent_rewards(agents, rows), agents)
    agent_plots.log_agent_series(rec, agent)
    graph_rules.log_rule_log(rec, data)
    graph_rules.log_changed(rec, data)
    graph_rules.log_why(rec, ctx.con, data, options.why_atoms, options.why_depth, lambda: ctx.model,
                        drawn.edge_counts)
    return data
