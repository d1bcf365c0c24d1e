"""The traced evaluation games of a run (a training's, `tracelab eval --run`'s), for the trace's `]` / `[` keys and its header line.

A training run (HELPER_GUIDE's contract, docs/training.md) begins each evaluation game with the info
`{"kind": "eval", "train_step": N, "eval_round": K, "params": {...}}` and stores its full trace; `tracelab
eval --run` begins each of its games with `{"kind": "eval", "params": {...}}` (the world's params: what the
game was played against, tracelab.store.eval_params). A run with no evaluation games has none. Read from the
begin info itself, so a run sealed before the episodes view had its `kind` column reads the same."""
from __future__ import annotations

from dataclasses import dataclass

from tracelab.store.eval_params import EVAL_PARAMS_COLUMNS, eval_params_text
from tracelab.viewers.tui.source import RunSource

HEADER_WIDTH = 79     # the header line's game part, after its leading space, fits an 80-column terminal
MIN_PARAMS_ROOM = 8  # less room than this: no params rather than a stump of them

# every evaluation game in episode order; nth / of: its place among the games of its evaluation round
EVAL_GAMES_SQL = f"""
SELECT episode, train_step, eval_round, params, level, outcome, steps,
       row_number() OVER (PARTITION BY train_step, eval_round ORDER BY episode) AS nth,
       count(*) OVER (PARTITION BY train_step, eval_round) AS of_round
FROM (SELECT episode, outcome, steps,
             TRY_CAST(json_extract(begin_info, '$.train_step') AS BIGINT) AS train_step,
             TRY_CAST(json_extract(begin_info, '$.eval_round') AS BIGINT) AS eval_round,
             {EVAL_PARAMS_COLUMNS}
      FROM episodes WHERE json_extract_string(begin_info, '$.kind') = 'eval')
ORDER BY episode
"""


@dataclass(frozen=True)
class EvalGame:
    episode: int
    train_step: int | None
    eval_round: int | None
    params: str | None         # the world's params (JSON text) where its begin info records them
    level: float | None        # an older run's level instead (RuleSim's opponent p)
    outcome: str | None        # None while the game is still being played (a live run)
    steps: int | None
    nth: int                   # 1-based place among the games of its evaluation round
    of_round: int

    def describe(self) -> str:
        """One line for the trace's header (fits 80 columns; the episode number is in the status line)."""
        parts = [f"eval game {self.nth}/{self.of_round}"]
        if self.eval_round is not None:
            parts.append(f"round {self.eval_round}")
        if self.train_step is not None:
            parts.append(f"train step {self.train_step:,}")
        ended = "playing" if self.outcome is None else \
            f"{self.outcome}, {self.steps} steps" if self.steps is not None else self.outcome
        room = HEADER_WIDTH - len(" · ".join([*parts, ended, ""]))  # the params take what the rest leaves
        played_against = eval_params_text(self.params, self.level, room) if room >= MIN_PARAMS_ROOM else None
        return " · ".join([*parts, *([played_against] if played_against else []), ended])


def eval_games(source: RunSource) -> list[EvalGame]:
    """The run's evaluation games in episode order (empty: not a training run). A few per evaluation,
    so reading them all on each key press is cheap, and a live run's new games appear."""
    return [EvalGame(**row) for row in source.rows(EVAL_GAMES_SQL)]


def neighbour(games: list[EvalGame], episode: int | None, forward: bool) -> EvalGame | None:
    """The first game after `episode` (forward) or the last before it; from no episode, the first or
    the last game."""
    if episode is None:
        return (games[0] if forward else games[-1]) if games else None
    if forward:
        return next((g for g in games if g.episode > episode), None)
    return next((g for g in reversed(games) if g.episode < episode), None)
