"""One episode of any run as one rerun recording: the board (a run whose world declares a `[board]`:
viewers/board_state.py) or else the run's graph, the fired rules, the changes per step, the step and
why documents, the state lanes, the rewards and returns, the agent's plots and the blueprint (docs/replay.md)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import rerun as rr
from tracelab.viewers.replay import agent_plots, board_layer, graph_layer, graph_rules, lanes, plots
from tracelab.viewers.replay.blueprint import board_view, graph_view, replay_blueprint
from tracelab.viewers.replay.graph_layout import fit_given, layout
from tracelab.viewers.replay.graph_run import GraphEpisode, RunGraph, read_episode

from tracelab.board import Board
from tracelab.store.model import RunModel
from tracelab.store.reader import RunConnection
from tracelab.viewers.board_state import board_of_run, piece_color

APPLICATION_ID = "tracelab-replay"


@dataclass
class ReplayOptions:
    why_depth: int = 6
    lanes: tuple[str, ...] = lanes.DEFAULT_LANES
    open_at: str = "start"          # where the viewer's time cursor starts: start | end
    color_by: str | None = None     # a run without a board: the predicate colouring the nodes (None: default)
    why_atoms: tuple[str, ...] = () # the atoms whose why-trees the step documents show


@dataclass
class RunContext:
    """What every episode of a run shares: its board (None: its graph is drawn instead, with the nodes'
    positions: the graph's own `x`/`y`, else a layout computed once), its program model (for the
    why-trees) and the lanes it can draw. `prefetch` reads the `steps`
    rewards of a batch of episodes in one query."""
    con: RunConnection
    name: str
    board: Board | None
    graph: RunGraph | None          # a run without a board's
    lanes: tuple[str, ...] = ()
    _positions: np.ndarray | None = None
    _model: RunModel | None = None
    _color_label: tuple[str | None] | None = None   # decided at the first episode, kept for the others
    _steps: dict[int, list[plots.StepRow]] = field(default_factory=dict)

    @classmethod
    def of(cls, con: RunConnection, name: str) -> RunContext:
        board = board_of_run(con)
        return cls(con, name, board, None if board is not None else RunGraph.read(con))

    def positions(self, episode: int) -> np.ndarray:
        """[nodes, 2] float32 drawing positions of a run without a board, decided at the first episode."""
        assert self.graph is not None
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
        """--color-by, or the default of the first episode replayed (every recording colours alike); None
        on a board."""
        if self.graph is None:
            return None
        if self._color_label is None:
            self._color_label = (self.graph.color_label(self.con, wanted, episode),)
        return self._color_label[0]

    @property
    def model(self) -> RunModel:
        if self._model is None:
            self._model = RunModel(self.con)
        return self._model

    def check(self, options: ReplayOptions, episode: int) -> None:
        """The user's names before anything is drawn: --color-by, --why and --lanes (one-line errors)."""
        if self.board is not None and options.color_by is not None:
            raise ValueError("--color-by colours a graph's nodes; this run's episodes are drawn on its world's "
                             "board (--lanes draws a predicate's states, --why an atom's why-trees)")
        self.color_label(options.color_by, episode)
        graph_rules.check_atoms(self.model, options.why_atoms)
        self.lanes = lanes.check_lanes(self.con, options.lanes)

    def prefetch(self, episodes: list[int]) -> None:
        """The `steps` rows of these episodes in one query (the rest of an episode is read when it is
        recorded: a reasoning's rows may be millions)."""
        rows = plots.step_rows(self.con, episodes)
        self._steps.update({e: rows.get(e, []) for e in episodes})

    def step_rows(self, episode: int) -> list[plots.StepRow]:
        """The episode's `steps` rows (prefetched ones from memory, once)."""
        if episode not in self._steps:
            return plots.step_rows(self.con, [episode]).get(episode, [])
        return self._steps.pop(episode)

    def record(self, episode: int, rec: rr.RecordingStream, options: ReplayOptions, blueprint: bool = True,
               last_step: int = 0) -> GraphEpisode:
        return record_episode(self, episode, rec, options, blueprint, last_step)


def new_recording(run_name: str, episode: int) -> rr.RecordingStream:
    return rr.RecordingStream(APPLICATION_ID, recording_id=f"{run_name}/episode-{episode}")


def record_episode(ctx: RunContext, episode: int, rec: rr.RecordingStream, options: ReplayOptions | None = None,
                   blueprint: bool = True, last_step: int = 0) -> GraphEpisode:
    """Log one episode into `rec` (which already has its sink). The blueprint belongs to the application,
    so one per output is enough (`blueprint`: send it with this one; its step axes end at `last_step`, or
    at this episode's end if later)."""
    options = options or ReplayOptions()
    label = ctx.color_label(options.color_by, episode)
    data = read_episode(ctx.con, ctx.graph, episode, label, edges=ctx.board is None)
    rec.send_recording_name(f"{ctx.name} episode {episode} ({data.outcome or 'running'}, {data.steps} steps)")
    rows = ctx.step_rows(episode)
    agent = agent_plots.read_series(ctx.con, episode)
    if blueprint:
        main = board_view(ctx.board) if ctx.board is not None else graph_view(ctx.positions(episode), label)
        rec.send_blueprint(replay_blueprint(main, options.open_at, max(last_step, data.steps - 1), bool(rows),
                                            bool(agent.values), bool(agent.terms),
                                            bool(ctx.lanes)))
    board = ctx.board

    def colour_of(agent: str) -> tuple[int, int, int] | None:
        return None if board is None else piece_color(board, agent)

    edges, deaths = graph_rules.no_edges, {}
    players = {agent for _, agent, *_ in rows}     # who acted; on a board also the pieces that can die
    if board is not None:
        track = board_layer.log_board(rec, ctx.con, board, episode)
        deaths = track.deaths()
        players |= {p.thing for state in track.states for p in state.pieces if board.pieces[p.kind].alive}
    else:
        edges = graph_layer.log_graph(rec, ctx.graph, ctx.positions(episode), data).edge_counts
    if rows:
        agents = list(dict.fromkeys(agent for _, agent, *_ in rows))
        plots.log_rewards(rec, plots.agent_rewards(agents, rows), agents, [colour_of(a) for a in agents])
    agent_plots.log_agent_series(rec, agent, colour_of)
    # the default lanes follow a game's agents, the policy's and the scripted ones (its bullets' atLoc
    # would crowd them); --lanes shows all
    lanes.log_lanes(rec, ctx.con, episode, ctx.lanes, rows,
                    agents=players if options.lanes == lanes.DEFAULT_LANES and players else None)
    graph_rules.log_rule_log(rec, data)
    graph_rules.log_changed(rec, data)
    notes = plots.step_notes(rows)
    game = plots.eval_game_note(ctx.con, episode)
    if game is not None:
        notes = {s: [game, *notes.get(s, [])] for s in range(data.steps)}
    graph_rules.log_why(rec, ctx.con, data, options.why_atoms, options.why_depth, lambda: ctx.model, edges, deaths,
                        notes)
    return data
