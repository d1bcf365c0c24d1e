"""What a world's registration adds to its spec where the generic stack meets files and settings the spec
does not hold: checkpoints and runs an earlier tracelab wrote for it, and the env its evaluations play. The
generic modules (env_checkpoint, external_eval, reward_rescore, ...) ask here and name no world; a world's
registration module (the war game's: envs/declared/gridwar_runs.py) answers, imported on the first question
only (by name: asking loads none of it, nor tracelab.envs's ids, until then, and the layers stay one-way)."""
from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tracelab.envs.declared.env_source import EnvSource

# the registrations with extras: each module has the functions named below (a question it has no answer
# for returns None)
REGISTRATIONS = ("tracelab.envs.declared.gridwar_runs",)


def _answers(question: str) -> list[Callable[..., Any]]:
    return [getattr(importlib.import_module(m), question) for m in REGISTRATIONS]


def _first(question: str, *args: Any) -> Any:
    return next((a for a in (f(*args) for f in _answers(question)) if a is not None), None)


def retired_checkpoint(state: Mapping[str, Any] | None, pickled: bytes, where: str) -> str | None:
    """The line refusing a checkpoint an earlier trainer of a world wrote (`state`: the loaded one, None when
    it would not load safely; `pickled`: its bytes' start), saying how to go on; None when no world's."""
    return _first("retired_checkpoint", state, pickled, where)


def old_run_terms(config: Mapping[str, Any]) -> list[Any] | None:
    """A run's reward terms (reward_rescore.Term) from the config of a run an earlier tracelab wrote for a
    world (no spec in the run), or None."""
    return _first("old_run_terms", config)


def evaluation_env(source: EnvSource, level: float) -> EnvSource | None:
    """The env a training's evaluations play on `source` at the evaluation `level` a world's registration
    gives a meaning to (the war game: its scripted opponent's p), or None: `source` itself."""
    return _first("evaluation_env", source, level)
