"""The Rules view: firings per rule (total, episodes it fired in, per outcome of those episodes; on a run
that is not of games, a reasoning run, the first and last t it fired at) with the rules that never fired
listed as such (coverage); `e` switches to firings per episode and rule. Enter on a
rule filters the trace by it."""
from __future__ import annotations

from typing import Any

from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.reactive import reactive
from textual.widgets import Static

from tracelab.viewers.tui.colours import FALSE
from tracelab.viewers.tui.lazy_table import Column, LazyTable
from tracelab.viewers.tui.messages import OpenTrace
from tracelab.viewers.tui.paging import QuerySource
from tracelab.viewers.tui.source import RunSource, background
from tracelab.engine.terminal_text import printable

PER_RULE_SQL = """
SELECT r.name AS rule, count(c.seq) AS firings, count(DISTINCT c.episode) AS episodes,
       count(c.seq) FILTER (e.outcome = 'win') AS in_wins,
       count(c.seq) FILTER (e.outcome = 'loss') AS in_losses,
       count(c.seq) FILTER (e.outcome NOT IN ('win', 'loss')) AS in_other,
       min(c.t) AS first_t, max(c.t) AS last_t,
       min(c.episode) AS first_episode, r.delay, r.immediate, r.rule AS rule_id
FROM raw.rules r
LEFT JOIN raw.changes c ON c.cause_kind = 2 AND c.cause_id = r.rule
LEFT JOIN raw.episode_end e ON e.episode = c.episode
GROUP BY r.rule, r.name, r.delay, r.immediate
"""
PER_EPISODE_SQL = """
SELECT episode, rule, count(*) AS firings, min(t) AS first_t, max(t) AS last_t
FROM firings GROUP BY episode, rule
"""


def _firings(row: dict[str, Any]) -> Text:
    n = row["firings"]
    return Text("never", style=f"bold {FALSE}") if n == 0 else Text(f"{n:,}")


PER_RULE_COLUMNS = [
    Column("rule", "rule", 22), Column("firings", "firings", 9, align="right", render=_firings),
    Column("episodes", "eps", 5, align="right"), Column("in_wins", "in wins", 8, align="right"),
    Column("in_losses", "in losses", 9, align="right"), Column("in_other", "other", 7, align="right"),
    Column("delay", "Δt", 3, align="right"),
]
BOARDLESS_PER_RULE_COLUMNS = [
    Column("rule", "rule", 22), Column("firings", "firings", 9, align="right", render=_firings),
    Column("episodes", "eps", 5, align="right"), Column("first_t", "first t", 7, align="right"),
    Column("last_t", "last t", 7, align="right"), Column("delay", "Δt", 3, align="right"),
]
PER_EPISODE_COLUMNS = [
    Column("episode", "episode", 8, align="right"), Column("rule", "rule", 22),
    Column("firings", "firings", 9, align="right"), Column("first_t", "first t", 7, align="right"),
    Column("last_t", "last t", 7, align="right"),
]


class RulesPane(Vertical):
    BINDINGS = [Binding("e", "toggle_view", "per episode/rule")]
    per_episode = reactive(False, init=False)   # firings per (episode, rule) instead of per rule (e)

    def __init__(self, source: RunSource) -> None:
        super().__init__()
        self.source = source
        self.loaded = False

    @property
    def per_rule_columns(self) -> list[Column]:
        return PER_RULE_COLUMNS if self.source.games else BOARDLESS_PER_RULE_COLUMNS

    def compose(self) -> ComposeResult:
        yield LazyTable(self.per_rule_columns, id="rules-table")
        yield Static("", id="rules-status", classes="status")

    @property
    def table(self) -> LazyTable:
        return self.query_one("#rules-table", LazyTable)

    @property
    def status(self) -> Static:
        return self.query_one("#rules-status", Static)

    def focus_default(self) -> None:
        if not self.loaded:
            self.loaded = True
            self.reload()
        self.table.focus()

    def reload(self) -> None:
        table = self.table
        if self.per_episode:
            table.set_source(QuerySource(self.source, PER_EPISODE_SQL, "episode, firings DESC, rule"),
                             PER_EPISODE_COLUMNS)
        else:
            table.set_source(QuerySource(self.source, PER_RULE_SQL, "firings DESC, rule, rule_id"),
                             self.per_rule_columns)
        self.status.update(" counting firings… (Esc cancels)")

    def on_lazy_table_loaded(self, event: LazyTable.Loaded) -> None:
        event.stop()
        if self.per_episode:
            text = f" {event.count} (episode, rule) pairs · e: per rule · Enter: trace of the rule"
            self.status.update(text)
            return

        status = self.status   # queried here: the worker reads no widget (docs/tui.md)

        def work() -> None:
            never = self.source.scalar(f"SELECT count(*) FROM ({PER_RULE_SQL}) WHERE firings = 0")
            self.app.call_from_thread(status.update,
                                      f" {event.count} rules, {never} never fired · e: per episode · "
                                      f"Enter: trace filtered by the rule")

        self.run_worker(background(work), thread=True, group="rules-never", exclusive=True, exit_on_error=False)

    def action_toggle_view(self) -> None:
        self.per_episode = not self.per_episode

    def watch_per_episode(self) -> None:
        self.reload()

    def on_lazy_table_row_selected(self, event: LazyTable.RowSelected) -> None:
        event.stop()
        row = event.row
        if row is None:
            return
        # per episode: that episode; per rule: the episode open in the trace, else the rule's first
        episode = row["episode"] if "episode" in row else getattr(self.screen, "episode", None)
        if episode is None:
            episode = row.get("first_episode")
        if episode is None:
            self.notify(printable(f"rule {row['rule']} never fired: no trace to show"), severity="warning",
                        markup=False)
            return
        self.post_message(OpenTrace(int(episode), rule=row["rule"]))
