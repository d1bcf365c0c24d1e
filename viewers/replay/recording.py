"""One traced episode as one rerun recording: the board, the fired rules, the state lanes, the why
documents, the plots and the blueprint."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import rerun as rr

from tracelab.store.board import BoardLoader, EpisodeBoard
from tracelab.store.model import RunModel
from tracelab.store.reader import RunConnection
from tracelab.viewers.replay import board_layer, plots, rules_layer
from tracelab.viewers.replay.blueprint import replay_blueprint

APPLICATION_ID = "tracelab-replay"


@dataclass
class ReplayOptions:
    why_depth: int = 6
    lanes: tuple[str, ...] = rules_layer.LANE_LABELS
    open_at: str = "start"          # where the viewer's time cursor starts: start | end


@dataclass
class RunContext:
    """What every episode of a run shares: its board loader (cast, vocabulary), its program model (for
    the why-trees) and, for a training run, its metrics."""
    con: RunConnection
    name: str
    loader: BoardLoader
    model: RunModel
    metrics: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @classmethod
    def of(cls, con: RunConnection, name: str) -> "RunContext":
        return cls(con, name, BoardLoader(con), RunModel(con), plots.training_metrics(con))

    def refresh_metrics(self) -> None:
        self.metrics = plots.training_metrics(self.con)


def new_recording(run_name: str, episode: int) -> rr.RecordingStream:
    return rr.RecordingStream(APPLICATION_ID, recording_id=f"{run_name}/episode-{episode}")


def record_episode(ctx: RunContext, episode: int, rec: rr.RecordingStream,
                   options: ReplayOptions | None = None) -> EpisodeBoard:
    """Log one episode into `rec` (which already has its sink) and return its board."""
    options = options or ReplayOptions()
    board = ctx.loader.load(episode)
    rec.send_recording_name(f"{ctx.name} episode {episode} ({board.outcome or 'running'}, {board.steps} steps)")
    rec.send_blueprint(replay_blueprint(board.map, bool(ctx.metrics), options.open_at))
    board_layer.log_board(rec, board)
    rules_layer.log_rule_log(rec, board)
    rules_layer.log_lanes(rec, board, options.lanes)
    rewards = plots.team_rewards(ctx.con, board)
    if rewards is not None:
        plots.log_rewards(rec, rewards)
    rules_layer.log_why(rec, ctx.con, board, rewards, options.why_depth, ctx.model)
    if ctx.metrics:
        plots.log_training(rec, ctx.metrics)
    return board
