"""`tracelab compare RUN...`: training runs side by side, one column per run (named by its path as
given): how each ended, the config keys whose values differ between them, and each run's final metrics
(the value at its last step; win rates also at their best). Runs are read through the store's sandboxed
reader (tracelab.store.open_run), so a run from a stranger is only ever read as data."""
from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from functools import lru_cache
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from tracelab.commands._interrupt import ctrl_c_stops_queries
from tracelab.commands._output import write_rows, write_table
from tracelab.commands.show import OWN_SECTIONS
from tracelab.errors import UserError, store_errors
from tracelab.store.kind import spec_source_sql, spec_text_of, world_params
from tracelab.store.reader import query_readonly, resolve_run, retrying
from tracelab.store.several import SeveralRunsConnection, catalog_of, run_names
from tracelab.train.reward_scale import METHOD_REWARD_SCALE

if TYPE_CHECKING:
    from tracelab.store.reader import RunConnection

MAX_METRIC_NAMES = 200     # metric names read per run (a training writes about 15); the rest are named as a count
MAX_CONFIG_DEPTH = 4       # nested config deeper than this is shown as one value
BEST_OF = ("eval/win_rate", "eval/method_win_rate")  # metrics whose best value is shown beside the last
MISSING = "-"


@dataclass
class TrainingRun:
    label: str                                     # the run as the user named it (a column of the table)
    status: str
    config: dict[str, Any]                         # flattened: "lr", "scenario_toml.rewards.win", ...
    last_step: int
    # name -> (step of its last value, last value, (best value, its step) or None)
    metrics: dict[str, tuple[int, float | None, tuple[float, int] | None]] = field(default_factory=dict)
    more_metrics: int = 0                          # names beyond MAX_METRIC_NAMES, not read
    params: dict[str, Any] | None = None           # a spec world's params (store.kind.world_params)


def run(args: argparse.Namespace) -> int:
    repeated = next((r for i, r in enumerate(args.runs) if r in args.runs[:i]), None)
    if repeated is not None:
        raise UserError(f"run {repeated!r} is given twice")
    with store_errors(), ctrl_c_stops_queries():
        runs = read_training_runs(args.runs)
    rows = comparison_rows(runs, precise=args.format != "table")
    names = ["key", *("./key" if r.label == "key" else r.label for r in runs)]   # column names are unique
    if args.format == "table":
        write_rows(names, [False] * len(names), rows, args.output)
    else:
        # deferred: pyarrow, for --format csv/json/parquet only (a table prints from DuckDB's rows)
        import pyarrow as pa

        from tracelab.store.arrow_build import strings  # not pa.array of strings: it imports pandas (arrow_build)
        columns = [strings([r[i] for r in rows]) for i in range(len(names))]
        write_table(pa.Table.from_arrays(columns, names=names), args.format, args.output)
    if len(runs) > 1 and not any(key.startswith("config ") for key, *_ in rows):
        print("note: the runs' configs are the same", file=sys.stderr)
    for r in runs:
        if r.more_metrics:
            print(f"note: {r.label}: {r.more_metrics} more metric names not shown (tracelab sql {r.label} "
                  f"\"SELECT DISTINCT name FROM metrics\")", file=sys.stderr)
    return 0


# What compare reads of each run: its metadata row, its metrics, its spec (kind.spec_source_sql).
READ_TABLES = ("run", "metrics", "sources")


def read_training_runs(paths: list[str]) -> list[TrainingRun]:
    """The runs (as the user named them) read on one sandboxed connection: one DuckDB instance for them
    all, with views over only the tables compare reads (tracelab.store.several), each kind of row read
    for every run in one statement."""
    resolved = [resolve_run(p) for p in paths]
    con = SeveralRunsConnection(resolved, run_names(resolved), union_views=False, raw_tables=READ_TABLES)
    try:
        return retrying(lambda: _read_all(con, paths))
    finally:
        con.close()


def _each_run(sql: Callable[[str], str], count: int) -> str:
    """The rows of `sql(raw)` (`raw`: the schema of a run's raw tables) for each of `count` runs together,
    each row's run first (`i`)."""
    return " UNION ALL ".join(f"SELECT {i} AS i, * FROM ({sql(f'{catalog_of(i)}.raw')})" for i in range(count))


def _read_all(con: "RunConnection", paths: list[str]) -> list[TrainingRun]:
    """Each training run as training_run makes it, from three statements for them all."""
    def rows(sql: Callable[[str], str]) -> list[tuple]:
        return query_readonly(con, _each_run(sql, len(paths)) + " ORDER BY ALL").fetchall()

    heads = rows(lambda raw: f"SELECT status, config, board, command, (SELECT count(DISTINCT name) FROM "
                             f"{raw}.metrics), {spec_source_sql(raw)} FROM {raw}.run")
    last: list[list[tuple]] = [[] for _ in paths]
    for i, *row in rows(lambda raw: f"""
            SELECT name, max(step), arg_max_null(value, (step, time)) FROM {raw}.metrics
            WHERE name IN (SELECT DISTINCT name FROM {raw}.metrics ORDER BY name LIMIT {MAX_METRIC_NAMES})
            GROUP BY name"""):  # an aggregate, not a window: half the CPU
        last[i].append(tuple(row))
    best: list[dict[str, tuple]] = [{} for _ in paths]
    for i, name, step, value in rows(lambda raw: f"""
            SELECT name, step, value FROM {raw}.metrics
            WHERE name IN ({", ".join(_sql_text(n) for n in BEST_OF)}) AND NOT isnan(value)
            QUALIFY row_number() OVER (PARTITION BY name ORDER BY value DESC, step) = 1"""):
        best[i][name] = (value, step)
    return [training_run(path, head, last[i], best[i]) for i, (path, (_, *head)) in enumerate(zip(paths, heads))]


def training_run(path: str, head: list[Any], last: list[tuple], best_of: dict[str, tuple]) -> TrainingRun:
    """A training run from what _read_all read of it: `head` (status, config, board, command, how many
    metric names, its spec's source), each metric's last (name, step, value) in name order, the best
    (value, step) of BEST_OF's; a UserError (one line) for a run without metrics."""
    status, config_text, board, command, names, source = head
    config = _json_object(config_text)
    if not names:
        games = board is not None or spec_text_of(source, config) is not None
        raise UserError(f"{without_metrics(path, games, command)}: compare puts training runs side by side; "
                        f"`tracelab diff RUN_A RUN_B` compares the episodes of two runs")
    metrics = {name: (step, value, best_of.get(name) if name in BEST_OF else None) for name, step, value in last}
    params = world_params(config, spec_text_of(source, config))
    if params is not None:  # a spec world's: its texts are not settings, its params are listed as such
        config = {k: v for k, v in config.items() if k not in OWN_SECTIONS and k != "env"}
    return TrainingRun(path, str(status), flat_config(config), max(step for step, _, _ in metrics.values()),
                       metrics, max(0, names - MAX_METRIC_NAMES), params)


def without_metrics(path: str, games: bool, command: str | None) -> str:
    """What a run without metrics is, for a one-line error: "'PATH' is a play run (...)"; `games`: a run of
    games (RuleSim's board, or a spec world's: kind.is_game_run), else a reasoning."""
    if not games:
        what = "a reasoning run (a trace, no training metrics)"
    elif str(command or "").startswith("tracelab train"):
        what = "a training run without metrics yet (stopped before its first log)"
    else:
        what = "a play run (games, no training metrics)"
    return f"{path!r} is {what}"


def _sql_text(s: str) -> str:
    return "'" + s.replace("'", "''") + "'"


def _json_object(text: Any) -> dict[str, Any]:
    try:
        value = json.loads(text) if isinstance(text, str) else text
    except (ValueError, RecursionError):
        return {}
    return value if isinstance(value, dict) else {}


def flat_config(config: dict[str, Any], prefix: str = "", depth: int = 0) -> dict[str, Any]:
    """Nested config as dotted keys; the scenario's TOML (scenario_toml) as its fields, so that a
    difference in one reward shows as that reward."""
    out: dict[str, Any] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if key == "scenario_toml" and isinstance(value, str) and not prefix:
            value = _toml_fields(value)
        if isinstance(value, dict) and value and depth < MAX_CONFIG_DEPTH:
            out.update(flat_config(value, name + ".", depth + 1))
        else:
            out[name] = value
    return out


@lru_cache(maxsize=16)
def _toml_fields(text: str) -> dict[str, Any] | str:
    """A scenario's TOML as its fields, or the text when it does not read as TOML; read once per text
    (runs compared side by side mostly share their scenario). Callers do not change what it returns."""
    import tomllib  # deferred: only runs that recorded a scenario's TOML need it
    try:
        return tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError):
        return text


def differing_keys(configs: list[dict[str, Any]]) -> list[str]:
    """The keys whose value is not the same in every config (missing counts as a value)."""
    keys = sorted({k for c in configs for k in c})
    return [k for k in keys if len({_config_text(c.get(k, MISSING)) for c in configs}) > 1]


def _config_text(value: Any) -> str:
    if isinstance(value, str):
        return json.dumps(value) if "\n" in value else value   # one line per key
    try:
        return json.dumps(value, sort_keys=True)
    except (TypeError, ValueError, RecursionError):
        return str(value)


def reward_scale_of(config: dict[str, Any], method: bool = True) -> str:
    """The reward scale a run trained at; a config without one is from before the flag, when the learner
    saw the game's rewards as they are (the method's scale). `method`: a grid game's run (the method's
    scale is named as such)."""
    scale = config.get("reward_scale", METHOD_REWARD_SCALE)
    if not isinstance(scale, (int, float)) or isinstance(scale, bool):   # a stranger's config: as it is
        return _config_text(scale)
    return f"{scale:g}" + (" (the method's)" if scale == METHOD_REWARD_SCALE and method else "")


def _number(v: float | None, precise: bool) -> str:
    if v is None or math.isnan(v):
        return "nan" if v is not None else MISSING
    if precise:
        return repr(v)
    return f"{v:.4g}"


def comparison_rows(runs: list[TrainingRun], precise: bool = False) -> list[list[str]]:
    """The table: [key, one cell per run]. `precise`: numbers in full (CSV, JSON), else 4 digits."""
    rows = [["status", *(r.status for r in runs)], ["last step", *(str(r.last_step) for r in runs)],
            ["reward scale", *(reward_scale_of(r.config, r.params is None) for r in runs)]]  # it decides what learns
    for name in dict.fromkeys(k for r in runs for k in (r.params or {})):  # a spec world's own params, all
        rows.append([f"param {name}", *(MISSING if r.params is None or name not in r.params
                                        else _config_text(r.params[name]) for r in runs)])
    configs = [r.config for r in runs]
    for key in [k for k in differing_keys(configs) if k != "reward_scale"] if len(runs) > 1 else []:
        rows.append([f"config {key}", *(_config_text(c.get(key, MISSING)) for c in configs)])
    names = sorted({n for r in runs for n in r.metrics}, key=lambda n: (not n.startswith("eval/"), n))
    for name in names:
        cells = []
        for r in runs:
            if name not in r.metrics:
                cells.append(MISSING)
                continue
            step, value, _ = r.metrics[name]
            at = "" if step == r.last_step else f" @{step}"   # a metric that stopped before the run did
            cells.append(_number(value, precise) + at)
        rows.append([name, *cells])
        if name in BEST_OF:
            rows.append([f"{name} (best)", *(
                MISSING if r.metrics.get(name, (0, None, None))[2] is None else
                f"{_number(r.metrics[name][2][0], precise)} @{r.metrics[name][2][1]}" for r in runs)])
    return rows
