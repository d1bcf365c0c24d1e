"""What a sweep searches (tracelab sweep, docs/scaling.md "Sweeps"): TrainConfig settings fixed for every
trial, the fields searched (a grid of values, or a distribution to draw from), the number of samples, the
scheduler and the metric. Written on the command line or in a TOML file; checked here, with no Ray, so a
bad spec is one line naming the field or value before anything starts.

    --set steps=20000  --grid lr=1e-4,3e-4  --random reward_scale=loguniform:0.01,1  --samples 4

    samples = 4               # the TOML form of the same
    scheduler = "asha"
    [set]
    steps = 20000
    [grid]
    lr = [1e-4, 3e-4]
    [random]
    reward_scale = "loguniform:0.01,1"
"""
from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

from tracelab.engine.safe_files import FileRefused, path_inside, read_text
from tracelab.errors import UserError
from tracelab.train.config import TrainConfig, config_fields

if TYPE_CHECKING:
    from tracelab.train.memory import Limit

# deferred: the evaluators (torch, the engine), the spec reader (gymnasium's ids), the game's scenarios and memory's
# estimate, in the functions that use them: the sweep's parser (tracelab --help) imports this module for its choices

DISTRIBUTIONS = ("uniform", "loguniform", "randint", "choice")
SCHEDULERS = ("fifo", "asha")
MODES = ("max", "min")
DEFAULT_METRIC = "eval/method_win_rate"
MAX_TRIALS = 1_000           # a spec's trials (grid points x samples): refused past this, before any start
SPEC_FILE_CAP = 64 * 1024    # a sweep file is a few lines
FILE_KEYS = {"set", "grid", "random", "samples", "scheduler", "metric", "mode"}
# one sweep trains one scenario or world (its runs are compared with each other); where the runs go is --out's
# the war game's scenario settings (train's flags for it, its spec's params: gridwar_scenarios.SCENARIO_FLAGS)
SCENARIO_SETTINGS = {"scenario": "str", "agents": "int", "non_markov": "bool", "opponent_p": "float",
                     "eval_p": "float"}
NOT_SEARCHED = {**dict.fromkeys(SCENARIO_SETTINGS, "one sweep trains one scenario"),
                "env": "one sweep trains one world"}
ENV_KEY = "env"  # `--set env=SPEC_OR_ID`: the trials train on that env (train --env), not on a scenario


class SweepSpecError(UserError):
    """A bad sweep spec: the message names the field, value or file key."""


@dataclass(frozen=True)
class Axis:
    """One searched field: a grid of `values`, a `choice` among them, or a range (low, high) to draw from."""
    name: str
    kind: str                 # "grid" or one of DISTRIBUTIONS
    values: tuple[Any, ...]

    def describe(self) -> str:
        if self.kind == "grid":
            return f"{self.name} in {list(self.values)}"
        return f"{self.name} ~ {self.kind}{list(self.values)}"


@dataclass(frozen=True)
class SweepSpec:
    fixed: dict[str, Any] = field(default_factory=dict)  # TrainConfig fields every trial has
    axes: tuple[Axis, ...] = ()
    samples: int = 1           # draws of the random fields; with a grid, per grid point (Tune's num_samples)
    scheduler: str = "fifo"
    metric: str = DEFAULT_METRIC
    mode: str = "max"
    sources: dict[str, str] = field(default_factory=dict, compare=False)  # field -> where it was given
    env: str | None = None     # a spec file or a registered id: every trial is a `train --env` of it
    scenario: dict[str, Any] = field(default_factory=dict)  # else the war game's SCENARIO_SETTINGS given

    @property
    def trials(self) -> int:
        return math.prod(len(a.values) for a in self.axes if a.kind == "grid") * self.samples

    def base_config(self) -> TrainConfig:
        return TrainConfig(**self.fixed)


_TYPES = {**{f.name: str(f.type) for f in fields(TrainConfig)}, **SCENARIO_SETTINGS}


def field_name(text: str, where: str) -> str:
    """A TrainConfig field (or a SCENARIO_SETTINGS name) from its name or its flag (lr, learning-rate,
    reward_scale, reward-scale)."""
    names = {spelling: name for name in SCENARIO_SETTINGS for spelling in (name, name.replace("_", "-"))}
    for f in config_fields():
        for spelling in (f.name, f.flag, f.alias, f.name.replace("_", "-")):
            if spelling:
                names[spelling] = f.name
    key = text.strip().removeprefix("--")
    if key in names:
        return names[key]
    close = difflib.get_close_matches(key, list(names), n=1)
    hint = f" (did you mean {close[0]}?)" if close else ""
    raise SweepSpecError(f"{where}: TrainConfig has no field {key!r}{hint}")


def parse_value(name: str, text: Any, where: str) -> Any:
    """`text` (a command-line string, or a TOML value) as field `name`'s type."""
    kind = _TYPES[name]
    if not isinstance(text, str):  # from TOML: already typed
        if kind == "float" and isinstance(text, int) and not isinstance(text, bool):
            return float(text)
        expected = {"int": int, "float": float, "bool": bool, "str": str}[kind]
        if isinstance(text, expected) and not (expected is int and isinstance(text, bool)):
            return text
        raise SweepSpecError(f"{where}: {text!r} is not {'an int' if 'int' in kind else 'a ' + kind} ({name})")
    s = text.strip()
    try:
        if kind == "float":
            value = float(s)
            if not math.isfinite(value):
                raise ValueError
            return value
        if kind == "int":
            whole = float(s.replace("_", ""))
            if whole != int(whole):
                raise ValueError
            return int(s.replace("_", "")) if s.replace("_", "").lstrip("-").isdigit() else int(whole)
        if kind == "bool":
            return {"true": True, "false": False}[s.lower()]
        return s
    except (ValueError, KeyError, OverflowError):
        what = {"float": "a number", "bool": "true or false"}.get(kind, "an integer")
        raise SweepSpecError(f"{where}: {name} must be {what}, got {s!r}") from None


def _checked(fixed: dict[str, Any], name: str, value: Any, where: str) -> None:
    """TrainConfig's own checks on the value, with the fixed settings (lr > 0, p in [0, 1], ...)."""
    try:
        TrainConfig(**{**fixed, name: value})
    except ValueError as e:
        raise SweepSpecError(f"{where}: {e}") from None


def grid_axis(name: str, values: list[Any], fixed: dict[str, Any], where: str) -> Axis:
    if not values:
        raise SweepSpecError(f"{where}: no values")
    parsed = tuple(parse_value(name, v, where) for v in values)
    for v in parsed:
        _checked(fixed, name, v, where)
    return Axis(name, "grid", parsed)


def random_axis(name: str, text: str, fixed: dict[str, Any], where: str) -> Axis:
    """DIST:A,B (uniform, loguniform: a float in [A, B]; randint: an integer in [A, B]) or choice:V1,V2,..."""
    dist, sep, rest = text.partition(":")
    dist = dist.strip()
    if not sep or dist not in DISTRIBUTIONS:
        raise SweepSpecError(f"{where}: expected DIST:LOW,HIGH or choice:V1,V2 with DIST one of "
                             f"{', '.join(DISTRIBUTIONS[:3])}, got {text!r}")
    parts = [p for p in rest.split(",") if p.strip()]
    if dist == "choice":
        return Axis(name, "choice", grid_axis(name, parts, fixed, where).values)
    kind = _TYPES[name]
    if kind not in ("int", "float"):
        raise SweepSpecError(f"{where}: {name} is a {kind} field: it takes choice:V1,V2, not {dist}")
    if dist == "randint" and kind == "float" or dist != "randint" and kind != "float":
        right = "randint" if kind != "float" else "uniform or loguniform"
        raise SweepSpecError(f"{where}: {name} is a{'n int' if kind != 'float' else ' float'} field: use {right}")
    if len(parts) != 2:
        raise SweepSpecError(f"{where}: {dist} takes two bounds LOW,HIGH, got {rest!r}")
    low, high = (parse_value(name, p, where) for p in parts)
    if not low < high:
        raise SweepSpecError(f"{where}: the low bound {low:g} must be below the high bound {high:g}")
    if dist == "loguniform" and low <= 0:
        raise SweepSpecError(f"{where}: loguniform needs bounds above 0, got {low:g}")
    for v in (low, high):
        _checked(fixed, name, v, where)
    return Axis(name, dist, (low, high))


def _assignment(text: str, flag: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise SweepSpecError(f"{flag} {text!r}: expected FIELD=VALUES")
    return (ENV_KEY if name.strip() == ENV_KEY else field_name(name, f"{flag} {text}")), value


def build_spec(*, sets: list[str] = (), grids: list[str] = (), randoms: list[str] = (), file: str | None = None,
               samples: int | None = None, scheduler: str | None = None, metric: str | None = None,
               mode: str | None = None) -> SweepSpec:
    """The spec of a sweep file (if given) with the command line's settings added (a field given in both
    takes the command line's)."""
    raw: dict[str, dict[str, tuple[Any, str]]] = {"set": {}, "grid": {}, "random": {}}
    top: dict[str, Any] = {}
    if file is not None:
        raw, top = _read_file(file)
    for flag, texts, table in (("--set", sets, "set"), ("--grid", grids, "grid"), ("--random", randoms, "random")):
        for text in texts:
            name, value = _assignment(text, flag)
            for other in raw.values():
                other.pop(name, None)
            raw[table][name] = (value.split(",") if table == "grid" else value, f"{flag} {text}")
    fixed: dict[str, Any] = {}
    env = None
    for name, (value, where) in raw["set"].items():
        if name == ENV_KEY:
            if not isinstance(value, str) or not value.strip():
                raise SweepSpecError(f"{where}: env is a spec file or a registered id, got {value!r}")
            env = value.strip()
        else:
            fixed[name] = parse_value(name, value, where)
    scenario = {k: fixed.pop(k) for k in SCENARIO_SETTINGS if k in fixed}
    if env:
        from tracelab.envs.declared.gridwar_scenarios import scenario_settings_given
        refused = scenario_settings_given([k for k in (*scenario, *raw["grid"], *raw["random"])
                                           if k in SCENARIO_SETTINGS],
                                          f"a sweep of --set env={env} searches the DQN's settings only")
        if refused:
            raise SweepSpecError(refused)
    try:
        TrainConfig(**fixed)
    except ValueError as e:
        raise SweepSpecError(f"{_culprit(fixed, raw['set'])}: {e}") from None
    axes: list[Axis] = []
    for table in ("grid", "random"):
        for name, (value, where) in raw[table].items():
            if name in NOT_SEARCHED:
                raise SweepSpecError(f"{where}: {name} cannot be searched ({NOT_SEARCHED[name]}; --set it)")
            if table == "grid":
                if not isinstance(value, list):
                    raise SweepSpecError(f"{where}: a grid is a list of values, got {value!r}")
                axes.append(grid_axis(name, value, fixed, where))
            else:
                if not isinstance(value, str):
                    raise SweepSpecError(f"{where}: expected a string such as \"loguniform:0.01,1\", got {value!r}")
                axes.append(random_axis(name, value, fixed, where))
    if not axes:
        raise SweepSpecError("nothing to search: give --grid FIELD=V1,V2 or --random FIELD=DIST:LOW,HIGH "
                             "(or a sweep file with [grid] or [random])")
    sources = {name: where for table in raw.values() for name, (_, where) in table.items()}
    spec = SweepSpec(fixed, tuple(axes), sources=sources, **_top_level(top, samples, scheduler, metric, mode, env),
                     env=env, scenario=scenario)
    if spec.trials > MAX_TRIALS:
        raise SweepSpecError(f"{spec.trials:,} trials (grid points x samples): more than {MAX_TRIALS:,}")
    if spec.scheduler == "asha":
        cfg = spec.base_config()
        if not 0 < cfg.eval_every < cfg.steps:
            raise SweepSpecError(f"--scheduler asha stops trials at their evaluations: it needs eval_every "
                                 f"between 0 and steps ({cfg.steps}), got {cfg.eval_every} (--set eval_every=N)")
    return spec


def _culprit(fixed: dict[str, Any], given: dict[str, tuple[Any, str]]) -> str:
    """Where the first fixed setting that TrainConfig refuses on its own was given ("--set" if they are
    refused only together)."""
    for name, (_, where) in given.items():
        if name not in fixed:  # the env, a scenario setting
            continue
        try:
            TrainConfig(**{name: fixed[name]})
        except ValueError:
            return where
    return "--set"


def _top_level(top: dict[str, Any], samples: int | None, scheduler: str | None, metric: str | None,
               mode: str | None, env: str | None = None) -> dict[str, Any]:
    out = {**top, **{k: v for k, v in (("samples", samples), ("scheduler", scheduler), ("metric", metric),
                                      ("mode", mode)) if v is not None}}
    if "samples" in out and (isinstance(out["samples"], bool) or not isinstance(out["samples"], int)
                             or out["samples"] < 1):
        raise SweepSpecError(f"samples must be an integer of at least 1, got {out['samples']!r}")
    for key, allowed in (("scheduler", SCHEDULERS), ("mode", MODES)):
        if key in out and out[key] not in allowed:
            raise SweepSpecError(f"{key} must be one of {', '.join(allowed)}, got {out[key]!r}")
    if env is not None and "metric" not in out:  # every env's evaluation has it (a win rate, only some)
        out["metric"] = "eval/mean_return"
    known = evaluation_metrics()
    if "metric" in out and out["metric"] not in known:
        raise SweepSpecError(f"metric must be one of the evaluations' metrics ({', '.join(known)}), "
                             f"got {out['metric']!r}")
    return out


def evaluation_metrics() -> list[str]:
    """What a trainer's evaluation writes (Tune reads a trial at its evaluations): the spec path's
    (env_policy.EnvEvalResult), with the counts and win rates of a world that declares a win (the war game's
    scenarios; `--set env=...` only where its world declares one, `eval/mean_return` its default)."""
    from tracelab.train.env_policy import EnvEvalResult
    return list(EnvEvalResult(wins=0, win_steps=[0]).metrics())


def _read_file(path: str) -> tuple[dict[str, dict[str, tuple[Any, str]]], dict[str, Any]]:
    """A sweep file's tables (field -> (value, where: FILE:LINE:COLUMN: TABLE.KEY)) and top-level settings;
    a file is data only, and the scenario file it names lies inside its folder."""
    from tracelab.envs.declared.spec_file import KeyLines, SpecError, parse_toml
    try:
        text = read_text(path, SPEC_FILE_CAP, what="sweep file")
        data = parse_toml(text, path)
    except (FileRefused, SpecError) as e:
        raise SweepSpecError(str(e)) from None
    except OSError as e:
        raise SweepSpecError(f"{path}: cannot read: {e.strerror or e}") from None
    lines, keys = text.splitlines(), KeyLines.scan(text)

    def where(*key: str) -> str:
        n = keys.line(key)
        column = len(lines[n - 1]) - len(lines[n - 1].lstrip()) + 1 if n else 0
        return f"{path}:{n}:{column}: {'.'.join(key)}" if n else f"{path}: {'.'.join(key)}"

    unknown = sorted(set(data) - FILE_KEYS)
    if unknown:
        raise SweepSpecError(f"{where(unknown[0])}: unknown key (expected {', '.join(sorted(FILE_KEYS))})")
    tables: dict[str, dict[str, tuple[Any, str]]] = {}
    for table in ("set", "grid", "random"):
        entries = data.get(table, {})
        if not isinstance(entries, dict):
            raise SweepSpecError(f"{where(table)}: must be a table ([{table}])")
        tables[table] = {(ENV_KEY if k == ENV_KEY else field_name(k, where(table, k))): (v, where(table, k))
                         for k, v in entries.items()}
    if "scenario" in tables["set"]:
        tables["set"]["scenario"] = _scenario_inside(path, *tables["set"]["scenario"])
    if ENV_KEY in tables["set"]:
        tables["set"][ENV_KEY] = _spec_inside(path, *tables["set"][ENV_KEY])
    return tables, {k: data[k] for k in ("samples", "scheduler", "metric", "mode") if k in data}


def _scenario_inside(path: str, value: Any, where: str) -> tuple[Any, str]:
    """A sweep file's scenario: a built-in name, or a file relative to the sweep file's folder and inside
    it (links resolved): a stranger's sweep file never makes tracelab read /etc/passwd."""
    from tracelab.game.scenario import builtin_scenario_names
    if not isinstance(value, str) or value in builtin_scenario_names():
        return value, where
    try:
        return str(path_inside(os.path.dirname(os.path.abspath(path)), value)), where
    except FileRefused as e:
        raise SweepSpecError(f"{where}: {e}") from None


def _spec_inside(path: str, value: Any, where: str) -> tuple[Any, str]:
    """A sweep file's env: a registered id, or a spec file (.toml) relative to the sweep file's folder and
    inside it (links resolved)."""
    if not isinstance(value, str) or not value.strip().endswith(".toml"):
        return value, where
    try:
        return str(path_inside(os.path.dirname(os.path.abspath(path)), value.strip())), where
    except FileRefused as e:
        raise SweepSpecError(f"{where}: {e}") from None


def check_trials_memory(spec: SweepSpec, probe: tuple[Any, int, Any], limit: Limit) -> None:
    """Refuse a sweep whose largest trial would not fit `limit`, as `train` refuses a run, before Ray
    starts: each searched field at its value (a grid's, a choice's, a range's bound) that takes the most
    memory (each size grows the estimate whatever the others are), the others at the fixed settings.
    `probe`: env_source.probe_env of the trials' env (its encoder, action count and WorldSpec or None)."""
    from tracelab.train.memory import MemoryLimitExceeded, check_estimate, env_training_estimate, env_world_bytes
    from tracelab.train.qnet import NetSpec
    encoder, n_actions, world = probe
    world_bytes = env_world_bytes(world)

    def parts(cfg: TrainConfig) -> list[tuple[str, str, int]]:
        return env_training_estimate(cfg, NetSpec(encoder.size, cfg.hidden_sizes, n_actions, cfg.dueling),
                                     world_bytes)

    def estimate(settings: dict[str, Any]) -> int:
        return sum(b for *_, b in parts(TrainConfig(**settings)))

    largest = dict(spec.fixed)
    for axis in spec.axes:
        largest[axis.name] = max(axis.values, key=lambda v: estimate({**spec.fixed, axis.name: v}))
    try:
        trials = [TrainConfig(**largest)]
    except ValueError:  # the largest values of two fields do not go together: each one's trial alone
        trials = [TrainConfig(**{**spec.fixed, a.name: largest[a.name]}) for a in spec.axes]
    try:
        for cfg in trials:
            check_estimate(parts(cfg), limit)
    except MemoryLimitExceeded as e:
        name = field_name(e.flags.split()[0], "the estimate")
        raise SweepSpecError(f"{spec.sources.get(name, 'a trial')}: {e}") from None
