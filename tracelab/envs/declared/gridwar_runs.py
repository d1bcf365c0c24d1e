"""The war game's answers to world_extras.py's questions, part of its registration (gridwar.py): the files
RuleSim's trainer and tracer wrote (every war game run before it trained through its spec, issue 38) and the
evaluations' opponent. Its checkpoints are refused in one line giving the command that starts the run again;
its runs' reward terms are read from their scenario's [rewards], their grid from its size; a training's
evaluations play the scripted opponent at the evaluation's p; its runs' board is war.toml's, drawn with their
scenario's map; its ids map their keyword arguments onto the spec's params. Light at import: `tracelab
rewards`, the viewers and the traces' coordinates ask here."""
from __future__ import annotations

import shlex
import tomllib
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tracelab.board import Board
    from tracelab.envs.declared.env_source import EnvSource
    from tracelab.store.reward_rescore import Term

# deferred: the trainer's config (numpy) for a refused checkpoint's command, the ids (gymnasium) for an
# evaluation, the rewards' Term and the spec's board for an old run: each question loads what it needs

# RuleSim's trainer's checkpoints: its observations (RuleSim's, with the nearest bullet) and its replay of
# the worlds are not the spec's, so its networks and buffer cannot continue here honestly. Its format 1 held
# numpy objects (only an unpickler that runs code reads them): recognised by its mark in the pickle
RULESIM_FORMATS = ("tracelab-dqn-checkpoint/2",)
RULESIM_FORMAT_1 = b"tracelab-dqn-checkpoint/1"

# the terms as a run written by RuleSim's tracer names them (runs before the spec path) -> its scenario's
# [rewards] keys
RULESIM_TERMS = {"win": "win", "loss": "loss", "hit": "hit_opponent", "got_shot": "got_shot",
                 "step": "valid_action", "unsafe": "unsafe", "invalid": "invalid"}
RULESIM_TERM_NOTES = {
    "unsafe": "an unsafe move is refused by the game whatever its reward (the agent stays), and a learner "
              "trained with --mask never chooses one: re-scoring changes the reward only",
    "invalid": "a shot without ammo does nothing whatever its reward, and a learner trained with --mask "
               "never chooses one: re-scoring changes the reward only",
    "step": "the step term is not paid on a step with an unsafe or invalid action (those terms replace it)",
}
# those of its terms whose occurrences such a run does not hold where they are worth 0
RULESIM_UNCOUNTED_AT_ZERO = ("step",)


def retired_checkpoint(state: Mapping[str, Any] | None, pickled: bytes, where: str) -> str | None:
    """The line refusing a checkpoint of RuleSim's trainer at `where`, or None when it is not one."""
    if state is None:
        return f"{where}: a checkpoint of RuleSim's trainer in its first format (numpy objects, which only a " \
               f"loader that runs code reads); refused" if RULESIM_FORMAT_1 in pickled else None
    if state.get("format") not in RULESIM_FORMATS:
        return None
    return f"{where}: trained by tracelab's RuleSim trainer (before the war game trained through its spec), " \
           f"whose observations and worlds the spec path does not rebuild: start a new run with its settings: " \
           f"{_new_run_command(state.get('config'))}"


# the scenario's settings an earlier TrainConfig held (train.config.RETIRED_FIELDS), at their defaults then
_OLD_SCENARIO_FIELDS = {"scenario": "base", "agents": None, "non_markov": False, "opponent_p": 0.7, "eval_p": 0.3}


def _new_run_command(config: Any) -> str:
    """`tracelab train` with the flags of an old checkpoint's config that differ from the defaults, the
    scenario's settings (its fields then, train's flags for the scenario now) first (a stranger's: only known
    fields of the right types, quoted)."""
    from tracelab.train.config import RETIRED_FIELDS, TrainConfig, config_fields
    from tracelab.train.env_checkpoint import checkpoint_config
    from tracelab.validation import Mismatch, check
    out = ["tracelab train"]
    try:
        cfg = checkpoint_config({"config": config})
        old = {k: config.get(k, default) for k, default in _OLD_SCENARIO_FIELDS.items()}
        for name, value in old.items():
            check(value, RETIRED_FIELDS[name], f"config.{name}")
    except (ValueError, TypeError, AttributeError, Mismatch):
        return " ".join(out + ["--scenario NAME ..."])
    for name, value in old.items():
        if value != _OLD_SCENARIO_FIELDS[name]:
            out.append("--non-markov" if name == "non_markov" else f"--{name.replace('_', '-')} "
                                                                   f"{shlex.quote(str(value))}")
    default = TrainConfig()
    for f in config_fields():
        value = getattr(cfg, f.name)
        if value == getattr(default, f.name):
            continue
        if isinstance(value, bool):
            out.append(("--" if value else "--no-") + f.flag)
        else:
            out.append(f"--{f.flag} {shlex.quote(str(value))}")
    return " ".join(out)


def old_run_terms(config: Mapping[str, Any]) -> list[Term] | None:
    """A RuleSim run's terms from its scenario's [rewards] (_scenario), or None."""
    from tracelab.game.scenario import Rewards
    from tracelab.store.reward_rescore import Term, number
    s = _scenario(config)
    if s is None:
        return None
    given = s.get("rewards", {})
    given = given if isinstance(given, dict) else {}
    defaults = Rewards()  # a scenario's [rewards] key left out has the game's default
    return [Term(term, number(given.get(key, getattr(defaults, key)), {}),
                 notes=(f"{term}: {RULESIM_TERM_NOTES[term]}",) if term in RULESIM_TERM_NOTES else (),
                 counted_at_zero=term not in RULESIM_UNCOUNTED_AT_ZERO)
            for term, key in RULESIM_TERMS.items()]


def old_run_grid(config: Mapping[str, Any]) -> tuple[Any, Any] | None:
    """The width and height (unchecked) of a RuleSim run's scenario (_scenario), or None."""
    s = _scenario(config)
    return None if s is None else (s.get("width"), s.get("height"))


def evaluation_env(source: EnvSource, p: float) -> EnvSource | None:
    """One of the game's ids with its scripted opponent at the evaluation's `p` (p_toward), or None."""
    from tracelab.envs.declared.gridwar import GRIDWAR_SPEC_IDS
    return source.with_args(p_toward=p) if source.name in GRIDWAR_SPEC_IDS else None


def old_run_board(board_name: str | None, config: Mapping[str, Any]) -> Board | None:
    """war.toml's board for a RuleSim run (one declaring the board of the runs before boards were declared,
    BOARD_BEFORE_DECLARED), with its team size and ammo, drawn
    with the rows of the scenario's map (its width, height, mountains and bases): the `[data.maps]` entry
    they match, else the default's board with them; None for another run, or a config without a scenario
    that reads."""
    from dataclasses import replace

    from tracelab.board import MAX_RECORDED_SIDE
    from tracelab.envs.declared.gridwar import WAR_SPEC
    from tracelab.envs.declared.spec import load_spec
    from tracelab.store.schema import BOARD_BEFORE_DECLARED

    s = _scenario(config) if board_name == BOARD_BEFORE_DECLARED else None
    if s is None:
        return None
    try:
        w, h = int(s["width"]), int(s["height"])
        if not (0 < w <= MAX_RECORDED_SIDE and 0 < h <= MAX_RECORDED_SIDE):
            return None           # a stranger's config: no board rather than a grid of any size
        grid = [["."] * w for _ in range(h)]
        for x, y in s.get("mountains", []):
            grid[h - 1 - int(y)][int(x)] = "M"
        for key, ch in (("red_base", "r"), ("blue_base", "b")):
            x, y = s[key]
            grid[h - 1 - int(y)][int(x)] = ch
        params = {"agents_per_team": int(s.get("agents_per_team", 1)), "ammo": int(s.get("ammo", 3))}
    except (KeyError, TypeError, ValueError, IndexError):
        return None
    rows = ["".join(r) for r in grid]
    maps = tomllib.loads(WAR_SPEC.read_text())["data"]["maps"]
    name = next((m for m, v in maps.items() if v["rows"] == rows), "default")
    board = load_spec(WAR_SPEC, map=name, **params).board
    # a map of no [data.maps] entry (a scenario file's own): war.toml's board drawn with its rows
    return None if board is None else replace(board, rows=tuple(rows))


def _scenario(config: Mapping[str, Any]) -> dict[str, Any] | None:
    """The scenario a RuleSim run's config holds as TOML (train's `scenario_toml`; play's `scenario`, a name
    where scenario_toml is beside it), parsed; None when neither holds TOML that reads (a stranger's: its
    length bounded)."""
    from tracelab.store.kind import MAX_SPEC_TEXT
    text = next((t for t in (config.get("scenario_toml"), config.get("scenario")) if isinstance(t, str)
                 and "=" in t), None)  # TOML has a `key = value`, a name none
    if text is None or len(text) > MAX_SPEC_TEXT:
        return None
    try:
        return tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError):
        return None


def declared_id(name: str, kwargs: Mapping[str, Any]) -> tuple[str, dict[str, Any]] | None:
    """The spec file and params of one of the game's ids with its keyword arguments (the old env's names
    mapped onto the spec's: gridwar.spec_and_params), or None for another name."""
    from tracelab.envs.declared.gridwar import GRIDWAR_SPEC_IDS, spec_and_params
    if name not in GRIDWAR_SPEC_IDS:
        return None
    spec, params = spec_and_params(name, dict(kwargs))
    return str(spec), params
