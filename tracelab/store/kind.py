"""What kind of run a run is, as the run itself says: the board it declares, in its metadata (RunMeta.board,
the `board` column of the `run` view: runs written by RuleSim) or in its config (a spec world's `[board]`,
tracelab.board.board_of_config). A game run declares its board and viewers draw its episodes on it; a run
without a board (a reasoning run, `tracelab reason --run`) has only its trace, program and graph. The
store reads no game's vocabulary to tell them apart. What the run says of its world beyond that (a spec
world's board, params and wins) is in its config (`run_config`)."""
from __future__ import annotations

import json
from typing import Any

from tracelab.store.reader import RunConnection


def run_board(con: RunConnection) -> str | None:
    """The board the run declares, or None (runs written before boards were declared read as the grid
    game's: schema.BOARD_BEFORE_DECLARED)."""
    rows = con.execute("SELECT board FROM raw.run").fetchall()
    return rows[0][0] if rows else None


def has_board(con: RunConnection) -> bool:
    """Whether the run declares a board: RuleSim's grid (run_board) or a spec's `[board]` in its config."""
    from tracelab.board import board_of_config  # deferred: the why searches and tables never draw a board
    return run_board(con) is not None or board_of_config(run_config(con)) is not None


def is_game_run(con: RunConnection) -> bool:
    """A run of games: it declares a board (has_board), or its episodes have returns (a spec
    world's games, any env's); a reasoning run's have none."""
    return has_board(con) or bool(con.execute(
        "SELECT EXISTS (SELECT 1 FROM episodes WHERE reward IS NOT NULL)").fetchall()[0][0])


def can_read(con: RunConnection, needs: str | None) -> bool:
    """Whether a saved query that `needs` "games" or "board" (tracelab.store.queries) reads this run."""
    return needs is None or (has_board(con) if needs == "board" else is_game_run(con))


def run_config(con: RunConnection) -> dict[str, Any]:
    """The run's config (RunMeta.config), {} when it has none or it is not a JSON object (a run's config
    comes from anywhere: its readers check what they take from it)."""
    rows = con.execute("SELECT config FROM raw.run").fetchall()
    try:
        config = json.loads(rows[0][0]) if rows and rows[0][0] else {}
    except (TypeError, ValueError):
        return {}
    return config if isinstance(config, dict) else {}


MAX_SPEC_TEXT = 1 << 20  # a spec file's own limit


def spec_source_sql(raw: str = "raw") -> str:
    """The spec's text in the run's `sources` (`raw`: the schema of its raw tables) as a scalar subquery:
    a list of the text of its one row (NULL where the file was not UTF-8), [] where it has none."""
    return (f"(SELECT list(text) FROM (SELECT text FROM {raw}.sources WHERE role = 'spec' AND bytes <= "
            f"{MAX_SPEC_TEXT} LIMIT 1))")


def spec_text(con: RunConnection, config: dict[str, Any]) -> str | None:
    """A spec world's run's spec text (spec_text_of), read on `con`."""
    return spec_text_of(con.execute(f"SELECT {spec_source_sql()}").fetchall()[0][0], config)


def spec_text_of(source: list[str | None], config: dict[str, Any]) -> str | None:
    """A spec world's run's spec text: its `sources` row (role `spec`; `source` as spec_source_sql reads
    it), or in a run written before that table, its config's `spec`; None for a run of no spec world, or a
    spec past MAX_SPEC_TEXT bytes."""
    text = source[0] if source else config.get("spec")
    return text if isinstance(text, str) and len(text) <= MAX_SPEC_TEXT else None


def world_params(config: dict[str, Any], text: str | None) -> dict[str, Any] | None:
    """A spec world's run's params (the `[params]` of its spec's `text`, spec_text, with the run's keyword
    arguments over them: `play --env`'s `env_args`, `train --env`'s `env.kwargs`), or None for a run of no
    spec world. The spec's text is a stranger's: read with tomllib only, at most MAX_SPEC_TEXT characters."""
    import tomllib  # deferred: most readers of a run's kind never parse its spec

    if not isinstance(text, str) or len(text) > MAX_SPEC_TEXT:
        return None
    try:
        params = tomllib.loads(text).get("params", {})
    except (tomllib.TOMLDecodeError, RecursionError):
        return None
    env = config.get("env")
    given = config.get("env_args") if isinstance(config.get("env_args"), dict) else \
        env.get("kwargs") if isinstance(env, dict) and isinstance(env.get("kwargs"), dict) else {}
    return {**(params if isinstance(params, dict) else {}), **given}
