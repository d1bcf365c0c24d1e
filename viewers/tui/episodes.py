"""The Episodes view: outcome, return, length and seed of every episode; for a training run also its
kind (train / eval) and training step; for a run without a board (a reasoning run) its steps, last t
and what the reasoning was (which repeat, which episode of a fact table) instead of return and seed.
Sort by clicking a header or with s / S; filter by outcome, length (e.g. `10..50`, `>=20`) and kind.
Enter opens the episode's trace. On a live run the list is re-read when episodes begin or end, and once
more after the run closes."""
from __future__ import annotations

import json
import re
from typing import Any

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import Input, Select, Static

from tracelab.viewers.tui.colours import FALSE, PARTIAL, TRUE, UNKNOWN
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.messages import OpenTrace
from tracelab.viewers.tui.paging import QuerySource
from tracelab.viewers.tui.places import EpisodesPlace
from tracelab.viewers.tui.source import LiveReads, RunSource, background
from tracelab.viewers.tui.shown_text import shown

OUTCOME_COLOURS = {"win": TRUE, "loss": FALSE, "draw": PARTIAL, "truncated": UNKNOWN,
                   # a reasoning's: more steps would change nothing / it ran its steps / a step raised
                   "converged": TRUE, "stopped": PARTIAL, "failed": FALSE, "interrupted": FALSE}


def outcome_text(row: dict[str, Any]) -> Text:
    o = row.get("outcome") or ("running" if not row.get("ended") else "")
    return shown(o, OUTCOME_COLOURS.get(o, ""))


def _reward(row: dict[str, Any]) -> str:
    return "" if row.get("reward") is None else f"{row['reward']:g}"


BASE_COLUMNS = [
    Column("episode", "episode", 8, align="right"),
    Column("outcome", "outcome", 9, render=outcome_text),
    Column("reward", "return", 8, align="right", render=_reward),
    Column("steps", "length", 7, align="right"),
    Column("seed", "seed", 6, align="right"),
    Column("world", "world", 5, align="right"),
]


def _about(row: dict[str, Any]) -> str:
    """A reasoning episode's begin info, `repeat 1` or `episode a` (a fact table's), as short text."""
    try:
        info = json.loads(row.get("begin_info") or "{}")
    except ValueError:
        return str(row.get("begin_info"))
    return ", ".join(f"{k} {v}" for k, v in info.items()) if isinstance(info, dict) else str(info)


# a run without a board: no return, seed or world, but its last t and what each reasoning was (when the
# run says: `--repeat` and fact tables with episodes do)
BOARDLESS_COLUMNS = [
    Column("episode", "episode", 8, align="right"),
    Column("outcome", "outcome", 11, render=outcome_text),
    Column("steps", "steps", 7, align="right"),
    Column("t_end", "last t", 7, align="right"),
]
ABOUT_COLUMN = Column("begin_info", "reasoning", 24, render=_about, max_width=60)
TRAINING_COLUMNS = [Column("kind", "kind", 6), Column("train_step", "train step", 10, align="right")]
KINDS = [("train", "train"), ("eval", "eval")]   # the kind selector's options (a training run's episodes)

LIVE_REFRESH_S = 2.0
_LENGTH = re.compile(r"^\s*(?:(\d+)?\s*\.\.\s*(\d+)?|([<>]=?|=)\s*(\d+)|(\d+))\s*$")


def length_clause(text: str) -> str:
    """SQL for a length filter: `10..50`, `..30`, `>=20`, `<5`, `=15` or `15`; raises ValueError."""
    if not text.strip():
        return ""
    m = _LENGTH.match(text)
    if not m:
        raise ValueError(f"cannot read length filter {text!r}: write 10..50, >=20, <5 or 15")
    lo, hi, op, n, exact = m.groups()
    if exact is not None:
        return f"steps = {int(exact)}"
    if op is not None:
        return f"steps {op} {int(n)}"
    parts = ([f"steps >= {int(lo)}"] if lo else []) + ([f"steps <= {int(hi)}"] if hi else [])
    return " AND ".join(parts)


class EpisodesPane(Vertical):
    BINDINGS = [
        Binding("s", "sort(1)", "sort"),
        Binding("S", "sort(-1)", "reverse", show=False),
        Binding("f", "focus_filter", "filter"),
        Binding("o", "next_outcome", "outcome"),
        Binding("e", "eval_only", "eval games", show=False),
    ]

    def __init__(self, source: RunSource, place: EpisodesPlace | None = None) -> None:
        """`place`: where this run's Episodes were left earlier in the session (filters, sort, cursor)."""
        super().__init__()
        self.source = source
        self._reopen = place
        self._applied: tuple[object, object] | None = None   # the selectors' values the table shows
        self.training = False
        self.sort_key, self.sort_desc = "episode", False
        self.outcomes: list[str] = []      # the run's outcomes, the selector's options (o steps through them)
        self.columns = list(BASE_COLUMNS if source.games else BOARDLESS_COLUMNS)
        self._seen: dict | None = None     # episode counts last seen (live runs)
        self.live_reads = LiveReads(source)

    def compose(self) -> ComposeResult:
        with Horizontal(id="ep-filters"):
            yield Static("outcome", classes="label")
            yield Select([], prompt="all", id="ep-outcome", compact=True)
            yield Static("length", classes="label")
            yield Input(placeholder="10..50", id="ep-length", compact=True)
            # the kind selector is a training run's: mounted once the run is read (_inspected), so that the
            # first screen of any other run has six widgets fewer to style (issue 40)
        yield LazyTable(id="ep-table")
        yield Static("", id="ep-status", classes="status")

    @property
    def table(self) -> LazyTable:
        return self.query_one("#ep-table", LazyTable)

    @property
    def status(self) -> Static:
        return self.query_one("#ep-status", Static)

    @property
    def outcome_select(self) -> Select[str]:
        return self.query_one("#ep-outcome", Select)

    @property
    def kind_select(self) -> Select[str]:
        return self.query_one("#ep-kind", Select)

    @property
    def kind(self) -> object:
        """The kind selector's value; Select.NULL (all) on a run that is not a training (it has none)."""
        return self.kind_select.value if self.training else Select.NULL

    @property
    def length_input(self) -> Input:
        return self.query_one("#ep-length", Input)

    def focus_default(self) -> None:
        self.table.focus()

    def on_mount(self) -> None:
        self.run_worker(background(self._inspect), thread=True, exit_on_error=False)
        if self.source.live:  # a run being written: new episodes appear as they begin and end
            self.set_interval(LIVE_REFRESH_S, self._poll)

    def _poll(self) -> None:
        if (not self.live_reads.due or not hasattr(self, "base") or self.source.busy
                or not self.screen.is_current):
            return

        def work() -> None:
            with self.live_reads.read():
                mark = self.source.rows("SELECT count(*) AS n, count(ended_at) AS ended FROM episodes")[0]
                if mark != self._seen:
                    first = self._seen is None
                    self._seen = mark
                    if not first:
                        self.app.call_from_thread(self.reload, True)

        self.run_worker(background(work), thread=True, group="episodes-poll", exclusive=True, exit_on_error=False)

    def _inspect(self) -> None:
        cols = self.source.columns("SELECT * FROM episodes")
        kind = "kind" if "kind" in cols else "json_extract_string(begin_info, '$.kind')"
        step = ("train_step" if "train_step" in cols
                else "TRY_CAST(json_extract(begin_info, '$.train_step') AS BIGINT)")
        base = (f"SELECT episode, world, steps, outcome, reward, seed, ended, t_start, t_end, "
                f"{kind} AS kind, {step} AS train_step, begin_info FROM episodes")
        # the outcomes to filter by, whether it is a training (its episodes have kinds), whether its
        # episodes say what they reasoned about: one statement (each costs its planning)
        seen = self.source.rows(
            "SELECT coalesce((SELECT list(DISTINCT outcome ORDER BY outcome) FROM episodes WHERE outcome IS NOT "
            f"NULL), []) AS outcomes, count(kind) > 0 AS training, count(begin_info) > 0 AS about FROM ({base})")[0]
        self.app.call_from_thread(self._inspected, base, seen["outcomes"], seen["training"], seen["about"])

    def _inspected(self, base: str, outcomes: list[str], training: bool, about: bool = False) -> None:
        self.base, self.training = base, training
        if self.source.games or training:     # a training run's episodes are games, board or not
            self.columns = list(BASE_COLUMNS) + (TRAINING_COLUMNS if training else [])
        else:
            self.columns = list(BOARDLESS_COLUMNS) + ([ABOUT_COLUMN] if about else [])
        self.outcomes = outcomes
        self.outcome_select.set_options([(o, o) for o in outcomes])
        place, self._reopen = self._reopen, None
        if training:
            kind = {"value": place.kind} if place is not None and place.kind in dict(KINDS) else {}
            self.query_one("#ep-filters").mount(
                Static("kind", classes="label", id="ep-kind-label"),
                Select(KINDS, prompt="all", id="ep-kind", compact=True, **kind))
        if place is None:
            self.reload()
            return
        if place.outcome in outcomes:
            self.outcome_select.value = place.outcome
        self.length_input.value = place.length
        self.sort_key, self.sort_desc = place.sort_key, place.sort_desc
        self.reload(cursor=place.cursor)

    def place(self) -> EpisodesPlace:
        """Where the user is, for reopening the run later in the session."""
        outcome, kind = self.outcome_select.value, self.kind
        return EpisodesPlace(None if outcome is Select.NULL else str(outcome),
                             None if kind is Select.NULL else str(kind),
                             self.length_input.value, self.sort_key, self.sort_desc,
                             self.table.cursor)

    def reload(self, keep_cursor: bool = False, cursor: int = 0) -> None:
        if not hasattr(self, "base"):
            return
        where = []
        outcome = self.outcome_select.value
        self._applied = (outcome, self.kind)
        if outcome not in (Select.NULL, None):
            where.append("outcome = $outcome")
        kind = self.kind
        if kind not in (Select.NULL, None):
            where.append("kind = $kind")
        status = self.status
        try:
            length = length_clause(self.length_input.value)
        except ValueError as e:
            status.update(shown(str(e), "bold red"))
            return
        if length:
            where.append(length)
        params = {k: v for k, v in (("outcome", outcome), ("kind", kind)) if f"${k}" in " ".join(where)}
        sql = f"SELECT * FROM ({self.base})" + (f" WHERE {' AND '.join(where)}" if where else "")
        direction = " DESC" if self.sort_desc else ""
        order = f"{self.sort_key}{direction} NULLS LAST, episode"
        table = self.table
        table.sort_key, table.sort_desc = self.sort_key, self.sort_desc
        table.set_source(QuerySource(self.source, sql, order, params or None), self.columns,
                         cursor=table.cursor if keep_cursor else cursor)

    def on_lazy_table_loaded(self, event: LazyTable.Loaded) -> None:
        sort = f"sorted by {self.sort_key}{' (desc)' if self.sort_desc else ''}"
        self.status.update(
            f" {event.count} episode(s), {sort} · Enter: trace · s: sort · f: filter · o: outcome")

    def on_lazy_table_row_selected(self, event: LazyTable.RowSelected) -> None:
        event.stop()
        if event.row is not None:
            self.post_message(OpenTrace(int(event.row["episode"])))

    def on_lazy_table_header_clicked(self, event: LazyTable.HeaderClicked) -> None:
        event.stop()
        if self.sort_key == event.column.key:
            self.sort_desc = not self.sort_desc
        else:
            self.sort_key, self.sort_desc = event.column.key, False
        self.reload()

    def action_sort(self, step: int) -> None:
        keys = [c.key for c in self.columns]
        if step < 0:
            self.sort_desc = not self.sort_desc
        else:
            self.sort_key = keys[(keys.index(self.sort_key) + 1) % len(keys)]
            self.sort_desc = False
        self.reload()

    def action_focus_filter(self) -> None:
        self.length_input.focus()

    def action_next_outcome(self) -> None:
        """The outcome selector's next value: all, then each outcome of the run, then all again."""
        select = self.outcome_select
        values = [Select.NULL, *self.outcomes]
        at = values.index(select.value) if select.value in values else 0
        select.value = values[(at + 1) % len(values)]

    def action_eval_only(self) -> None:
        if self.training:
            self.kind_select.value = "eval"

    def on_select_changed(self, event: Select.Changed) -> None:
        # a value set in code (reopening the run) is already shown: its late message reloads nothing
        if (self.outcome_select.value, self.kind) != self._applied:
            self.reload()

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.reload()
        self.focus_default()
