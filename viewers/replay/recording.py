"""One traced episode as one rerun recording: the board, the fired rules, the state lanes, the why
documents, the plots (the agent's: agent_plots.py) and the blueprint."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import rerun as rr
from tracelab.viewers.replay import agent_plots, board_layer, plots, rules_layer
from tracelab.viewers.replay.blueprint import replay_blueprint

from tracelab.board import Board
from tracelab.viewers.board import BoardLoader, EpisodeBoard
from tracelab.viewers.board_state import board_of_run
from tracelab.store.model import RunModel
from tracelab.store.reader import RunConnection

APPLICATION_ID = "tracelab-replay"


@dataclass
class ReplayOptions:
    why_depth: int = 6
    lanes: tuple[str, ...] = rules_layer.LANE_LABELS
    open_at: str = "start"          # where the viewer's time cursor starts: start | end
    color_by: str | None = None     # a run without a board: the predicate colouring the nodes (None: default)
    why_atoms: tuple[str, ...] = () # a run without a board: the atoms whose why-trees the documents show


@dataclass
class RunContext:
    """What every episode of a run shares: its board loader (cast, vocabulary), its program model (for
    the why-trees) and, for a training run, its metrics. `prefetch` reads what a batch of episodes needs
    in a few queries instead of a few per episode."""
    con: RunConnection
    name: str
    loader: BoardLoader
    board: Board | None             # what the board layer draws (war.toml's for a RuleSim run)
    metrics: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    _model: RunModel | None = None
    _rewards: dict[int, list[tuple[int, str, float]]] = field(default_factory=dict)
    _groundings: np.ndarray | None = None     # the prefetched episodes' groundings, for the model

    @classmethod
    def of(cls, con: RunConnection, name: str) -> RunContext:
        return cls(con, name, BoardLoader(con), board_of_run(con), plots.training_metrics(con))

    def prefetch(self, episodes: list[int]) -> None:
        """Read these episodes' change rows, outcomes, grounding texts and `steps` rewards, one query each;
        their groundings go to the model when a why-tree is first wanted."""
        self._groundings = self.loader.prefetch(episodes)
        rewards = plots.step_rewards(self.con, episodes)
        self._rewards.update({e: rewards.get(e, []) for e in episodes})

    def step_rewards(self, episode: int) -> list[tuple[int, str, float]]:
        """The episode's `steps` rows (prefetched ones from memory, once)."""
        if episode not in self._rewards:
            return plots.step_rewards(self.con, [episode]).get(episode, [])
        return self._rewards.pop(episode)

    @property
    def model(self) -> RunModel:
        """The run's program model, read when a why-tree is first wanted; with the groundings of the
        prefetched episodes."""
        if self._model is None:
            self._model = RunModel(self.con)
        if self._groundings is not None:
            self._model.prefetch_groundings(self._groundings)
            self._groundings = None
        return self._model

    def refresh(self) -> None:
        """Catch up with a run being written: its metrics so far (the model reads a grown vocabulary
        by itself)."""
        self.metrics = plots.training_metrics(self.con)

    def check(self, options: ReplayOptions, episode: int) -> None:
        """The options of a run without a board have no meaning on a game's (one-line errors)."""
        if options.color_by is not None or options.why_atoms:
            raise ValueError(f"--{'color-by' if options.color_by is not None else 'why'} is for a run "
                             "without a board (a reasoning run); this run's episodes are games on its board, "
                             "whose replay explains each step's deaths and the game's end (--why-depth)")

    def record(self, episode: int, rec: rr.RecordingStream, options: ReplayOptions, blueprint: bool = True,
               last_step: int = 0) -> EpisodeBoard:
        return record_episode(self, episode, rec, options, blueprint, last_step)


def new_recording(run_name: str, episode: int) -> rr.RecordingStream:
    return rr.RecordingStream(APPLICATION_ID, recording_id=f"{run_name}/episode-{episode}")


def record_episode(ctx: RunContext, episode: int, rec: rr.RecordingStream,
                   options: ReplayOptions | None = None, blueprint: bool = True,
                   last_step: int = 0) -> EpisodeBoard:
    """Log one episode into `rec` (which already has its sink) and return its board. The blueprint
    belongs to the application, so one per output is enough (`blueprint`: send it with this one; its
    step axes end at `last_step`, or at this episode's end if later)."""
    options = options or ReplayOptions()
    board = ctx.loader.load(episode)
    rec.send_recording_name(f"{ctx.name} episode {episode} ({board.outcome or 'running'}, {board.steps} steps)")
    agent = agent_plots.read_series(ctx.con, episode)
    if blueprint:
        rec.send_blueprint(replay_blueprint(ctx.board, bool(ctx.metrics), options.open_at,
                                            max(last_step, board.steps), bool(agent.values), bool(agent.terms)))
    if ctx.board is not None:
        board_layer.log_board(rec, ctx.con, ctx.board, episode)
    rules_layer.log_rule_log(rec, board)
    rules_layer.log_lanes(rec, board, options.lanes)
    rewards = plots.team_rewards(board, ctx.step_rewards(episode))
    if rewards is not None:
        plots.log_rewards(rec, rewards)
    agent_plots.log_agent_series(rec, agent)
    rules_layer.log_why(rec, ctx.con, board, rewards, options.why_depth, lambda: ctx.model)
    if ctx.metrics:
        plots.log_training(rec, ctx.metrics)
    return board
