"""What a world's registration adds to its spec where the generic stack meets files and settings the spec
does not hold: checkpoints and runs an earlier tracelab wrote for it, the env its evaluations play, and ids
whose keyword arguments it maps onto the spec's params. The generic modules (env_checkpoint, external_eval,
reward_rescore, env_source, coordinates, the viewers' board) ask here and name no world; a world's
registration module (the war game's: envs/declared/gridwar_runs.py) answers, imported on the first question
only (by name: asking loads none of it, nor tracelab.envs's ids, until then, and the layers stay one-way)."""
from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tracelab.board import Board

# the registrations with extras: each module has the functions named below (a question it has no answer
# for returns None)
REGISTRATIONS = ("tracelab.envs.declared.gridwar_runs",)


def _first(question: str, *args: Any) -> Any:
    """The first registration's answer that is not None, or None."""
    for module in REGISTRATIONS:
        answer = getattr(importlib.import_module(module), question)(*args)
        if answer is not None:
            return answer
    return None


def retired_checkpoint(state: Mapping[str, Any] | None, pickled: bytes, where: str) -> str | None:
    """The line refusing a checkpoint an earlier trainer of a world wrote (`state`: the loaded one, None when
    it would not load safely; `pickled`: its bytes' start), saying how to go on; None when no world's."""
    return _first("retired_checkpoint", state, pickled, where)


def old_run_terms(config: Mapping[str, Any]) -> list[Any] | None:
    """A run's reward terms (reward_rescore.Term) from the config of a run an earlier tracelab wrote for a
    world (no spec in the run), or None."""
    return _first("old_run_terms", config)


def evaluation_env(source: Any, level: float) -> Any:
    """The env (an EnvSource: not imported, which imports this module) a training's evaluations play on
    `source` at the evaluation `level` a world's registration gives a meaning to (the war game: its scripted
    opponent's p), or None: `source` itself."""
    return _first("evaluation_env", source, level)


def old_run_grid(config: Mapping[str, Any]) -> tuple[Any, Any] | None:
    """The width and height (unchecked) of the grid of a run an earlier tracelab wrote for a world before runs
    declared their grid (their config's `grid`: coordinates.py), from its config; or None."""
    return _first("old_run_grid", config)


def old_run_board(board_name: str | None, config: Mapping[str, Any]) -> Board | None:
    """The board of a run an earlier tracelab wrote for a world (no spec in the run; `board_name` the one
    the run declares, `config` its config), or None. Such a run names its cells by id (y·W + x)."""
    return _first("old_run_board", board_name, config)


def declared_id(name: str, kwargs: Mapping[str, Any]) -> tuple[str, dict[str, Any]] | None:
    """(the spec file, its params) of a registered id whose registration maps its keyword arguments onto the
    spec's params itself, or None for any other name."""
    return _first("declared_id", name, kwargs)
