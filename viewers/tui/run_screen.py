"""The screen of one open run: a tab per view (Episodes, Trace, Why, Rules, SQL, Training; a closed run
without metrics, a play or a reasoning, has no training curves and no Training tab), the keys 1-6 to switch, and the
messages that pass an episode, a rule or a change from one view to another. Its header follows the
run's life: live while written, then how it ended, then sealed.

The first screen is the Episodes table (or the view a reopened run was left on): every other view's module
is imported, and the view made, when it is first shown; the Trace view's modules, which Enter needs, in a
thread once the Episodes table is drawn with its cursor (issue 40: the board, plots and graph, numpy and
pyarrow are not loaded before: the Episodes table pages DuckDB's own rows)."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import Screen
from textual.widget import Widget
from rich.text import Text
from textual.widgets import Input, Static, TabbedContent, TabPane, Tabs

from tracelab.viewers.tui.episodes import EpisodesPane
from tracelab.viewers.tui.keybar import KeyBar
from tracelab.viewers.tui.lazy_table import LazyTable
from tracelab.viewers.tui.messages import ExplainAction, ExplainChange, OpenTrace
from tracelab.viewers.tui.places import RunPlace
from tracelab.viewers.tui.source import RunSource, SeveralRunsSource, background
from tracelab.viewers.tui.shown_text import shown

TABS = (("episodes", "1 Episodes"), ("trace", "2 Trace"), ("why", "3 Why"), ("rules", "4 Rules"),
        ("sql", "5 SQL"), ("training", "6 Training"))

# where Esc goes from a view: the why tree to the trace it explains, the trace to the run's episodes; any
# other view to the one the run opened on, and from that one back to the Runs screen
BACK = {"why": "trace", "trace": "episodes"}
EAGER = ("episodes",)   # built with the screen; the trace once it is drawn, the other views when first shown
STATUS_REFRESH_S = 1.0          # how often the run's status is read while it can change


class Panes(dict[str, Widget]):
    """The screen's views by tab, each made (its module imported) when first asked for."""

    def __init__(self, make: Callable[[str], Widget]) -> None:
        super().__init__()
        self._make = make

    def __missing__(self, tab: str) -> Widget:
        pane = self[tab] = self._make(tab)
        return pane


def _view_class(tab: str) -> type[Widget]:
    """The class of a tab's view, imported here: its module loads when the view is first made."""
    if tab == "episodes":
        return EpisodesPane
    if tab == "trace":
        from tracelab.viewers.tui.trace import TracePane
        return TracePane
    if tab == "why":
        from tracelab.viewers.tui.why import WhyPane
        return WhyPane
    if tab == "rules":
        from tracelab.viewers.tui.rules import RulesPane
        return RulesPane
    if tab == "sql":
        from tracelab.viewers.tui.sql import SqlPane
        return SqlPane
    from tracelab.viewers.tui.training import TrainingPane
    return TrainingPane


class RunTabs(TabbedContent):
    """TabbedContent that a stale message does not switch back. textual tells TabbedContent of a focus
    inside a pane, and of a tab becoming active, by messages; one still queued when a key (1-6, `w`, ...)
    switches views undid the switch (seen with fast keys on a loaded machine). Views switch by keys, tab
    clicks and the messages between views, so a focus reported from a hidden view, or the activation of a
    tab that is no longer the active one, is ignored."""

    def _on_tab_pane_focused(self, event: TabPane.Focused) -> None:
        if event.tab_pane.id != self.active:
            event.stop()
            event.prevent_default()   # textual runs every class's handler in the MRO unless this is set

    def _on_tabs_tab_activated(self, event: Tabs.TabActivated) -> None:
        if event.tab is not event.tabs.active_tab:
            event.stop()
            event.prevent_default()


class RunScreen(Screen):
    BINDINGS = [
        *(Binding(str(i + 1), f"show('{tab}')", title.split()[1], show=False) for i, (tab, title) in enumerate(TABS)),
        Binding("escape", "cancel_or_back", "back"),
    ]

    def __init__(self, path: Path, overlaid: Sequence[Path] = (), place: RunPlace | None = None,
                 keep_place: Callable[[RunPlace], None] | None = None) -> None:
        """`overlaid`: other runs whose curves the Training view draws with this one's (it opens first).
        `place`: where the user left this run earlier in the session (it opens there); `keep_place` is
        told where the user is each time the screen is left."""
        super().__init__()
        self.path = path
        self.source = RunSource(path)
        self.overlaid: list[RunSource] = []
        self.sql_source: RunSource | SeveralRunsSource = self.source
        try:
            for p in overlaid:
                self.overlaid.append(RunSource(p))
            if overlaid:   # the SQL console reads them all, every view with a `run` column
                self.sql_source = SeveralRunsSource([path, *overlaid])
        except BaseException:  # a run that does not open: close the ones opened, the screen is not shown
            self.on_unmount()
            raise
        self.initial = "training" if overlaid else "episodes"   # Esc from here closes the run
        self.place_left, self.keep_place = place, keep_place
        self.episode: int | None = None
        self._has_metrics: bool | None = None     # read once the run is no longer written
        arguments = {"episodes": lambda: (self.source, place.episodes if place else None),
                     "sql": lambda: (self.sql_source,), "training": lambda: (self.source, self.overlaid)}
        self.panes = Panes(lambda tab: _view_class(tab)(*arguments.get(tab, lambda: (self.source,))()))
        # reopened: on the view it was left on (the why tree: on the trace it explained)
        view = "trace" if place and place.view == "why" else place.view if place else self.initial
        self.opening = view if view in self.panes and self.has_view(view) else self.initial
        if self.opening == "episodes":
            # focused as the screen starts: textual's default (the first focusable widget) focused the tabs,
            # then the view its table, restyling the tabs' 11 nodes on each change (issue 40: the first screen)
            self.AUTO_FOCUS = "#ep-table"

    def compose(self) -> ComposeResult:
        yield Static(self._title(), id="title", classes="title")
        with RunTabs(initial=self.opening, id="tabs"):
            for tab, title in TABS:
                with TabPane(title, id=tab):
                    if tab in EAGER or tab == self.opening or (tab == "trace" and self._reopens_trace):
                        yield self.panes[tab]
        yield KeyBar()

    @property
    def _reopens_trace(self) -> bool:
        return self.place_left is not None and self.place_left.trace is not None

    def _title(self) -> Text:
        overlaid = f" + {len(self.overlaid)} overlaid in Training and SQL" if self.overlaid else ""
        return shown(f" {self.path.name}{overlaid}  ·  {self.source.state}  ·  {self.source.command}")

    def has_view(self, tab: str) -> bool:
        """Whether the run has this view: a closed run without metrics (a play, an evaluation, a reasoning)
        has no training curves to show."""
        if tab != "training" or self.source.live:
            return True
        if self._has_metrics is None:
            self._has_metrics = bool(self.source.scalar("SELECT count(*) FROM (SELECT 1 FROM metrics LIMIT 1)"))
        return self._has_metrics

    @property
    def tabs(self) -> RunTabs:
        return self.query_one("#tabs", RunTabs)

    def _hide_missing_views(self) -> None:
        for tab, _ in TABS:
            if not self.has_view(tab):
                self.tabs.hide_tab(tab)

    def on_mount(self) -> None:
        self._hide_missing_views()
        if self._reopens_trace:
            self.episode = self.place_left.trace.episode
            self.panes["trace"].reopen(self.place_left.trace)  # type: ignore[attr-defined]
        if self.source.can_change:  # its writer may close or die, `tracelab seal` may seal it
            self._status_timer = self.set_interval(STATUS_REFRESH_S, self._check_status)

    def on_lazy_table_loaded(self, event: LazyTable.Loaded) -> None:
        """The Episodes table is drawn with its cursor: import the Trace view's modules (its board, plots
        and graph, numpy, pyarrow) and read the run's board, which Enter opens, in a thread meanwhile
        (mounting it waits for Enter: a view mounted while the app closes would fail)."""
        if event.table.id == "ep-table" and "trace" not in self.panes:
            self.run_worker(background(self._preload_trace), thread=True, group="preload", exit_on_error=False)

    def _preload_trace(self) -> None:
        _view_class("trace")       # its modules: numpy and pyarrow with its paging, the board's drawing
        self.source.board          # noqa: B018 - read (and kept) for the trace's first compose

    def _check_status(self) -> None:
        if self.is_current:
            self.run_worker(self._read_status, thread=True, group="run-status", exclusive=True,
                            exit_on_error=False)

    def _read_status(self) -> None:
        if self.source.follow():
            self.app.call_from_thread(self._status_changed)

    def _status_changed(self) -> None:
        self.query_one("#title", Static).update(self._title())
        if not self.source.live and self.tabs.active != "training":
            self._hide_missing_views()
        if not self.source.can_change:
            self._status_timer.stop()

    async def pane(self, tab: str) -> Widget:
        """The view of a tab, mounted on first use (so that opening a run builds only two views)."""
        pane = self.panes[tab]
        if not pane.is_attached:
            await self.query_one(f"#{tab}", TabPane).mount(pane)
        return pane

    async def action_show(self, tab: str) -> None:
        if not self.has_view(tab):
            self.notify("this run has no training metrics: it is not a training (tracelab train --run)",
                        severity="warning")
            return
        await self.pane(tab)
        self.tabs.active = tab
        self.call_after_refresh(self._focus_pane, tab)

    def _focus_pane(self, tab: str) -> None:
        if self.tabs.active != tab:
            return  # focusing into a hidden pane would make TabbedContent switch back to it
        focus = getattr(self.panes[tab], "focus_default", None)
        if focus is not None and self.panes[tab].is_attached:
            focus()

    async def on_tabbed_content_tab_activated(self, event: TabbedContent.TabActivated) -> None:
        if event.pane.id:
            await self.pane(event.pane.id)
            self.call_after_refresh(self._focus_pane, event.pane.id)

    async def action_cancel_or_back(self) -> None:
        """Esc: cancel the running query the user waits on (not background work: a warm-up, a panel
        following the cursor); else leave a text field (for its view's table); else go back one view (BACK),
        and from the view the run opened on to the Runs screen."""
        if [source for source in self._sources() if source.interrupt_foreground()]:   # every one: no short cut
            self.notify("query cancelled")
            return
        # the SQL editor: to its results (where 1-6 work again). `get` does not make the view: textual's
        # TextArea (tree-sitter, its themes) is imported with the SQL view, not on the first screen
        sql = self.panes.get("sql")
        if sql is not None and sql.is_attached and sql.editor.has_focus:  # type: ignore[attr-defined]
            sql.action_focus_results()  # type: ignore[attr-defined]
            return
        if isinstance(self.focused, Input):
            self._focus_pane(self.tabs.active)
            return
        active = self.tabs.active
        if active == self.initial:
            self.app.close_run()  # type: ignore[attr-defined]
        else:
            await self.action_show(BACK.get(active, self.initial))

    def place(self) -> RunPlace:
        """Where the user is: the view, the Episodes' filters and cursor, the trace's episode and cursor."""
        episodes, trace = self.panes["episodes"], self.panes.get("trace")
        assert isinstance(episodes, EpisodesPane)
        return RunPlace(self.tabs.active or self.initial,
                        episodes.place() if episodes.is_mounted else None,
                        None if trace is None else trace.place())  # type: ignore[attr-defined]

    def on_screen_suspend(self) -> None:
        self.keep_where()   # left (back to the Runs screen, or a dialog over it)

    def keep_where(self) -> None:
        """Tell keep_place where the user is (also called by the app before it leaves the run: the
        suspend message comes only after the Runs screen is made, and Enter there may come first)."""
        if self.keep_place is not None:
            self.keep_place(self.place())

    def _sources(self) -> list[RunSource | SeveralRunsSource]:
        """Every connection the screen holds (the SQL console's own one for several runs)."""
        return [self.source, *self.overlaid, *([self.sql_source] if self.sql_source is not self.source else [])]

    def on_unmount(self) -> None:
        for source in self._sources():
            source.close()

    # ---- passing things between views ------------------------------------------------------------------
    async def on_open_trace(self, message: OpenTrace) -> None:
        self.episode = message.episode
        trace = await self.pane("trace")
        trace.show_episode(message.episode, rule=message.rule, at_t=message.at_t)  # type: ignore[attr-defined]
        await self.action_show("trace")

    async def on_explain_change(self, message: ExplainChange) -> None:
        why = await self.pane("why")
        why.explain(message.episode, message.atom, message.t, message.seq)  # type: ignore[attr-defined]
        await self.action_show("why")

    async def on_explain_action(self, message: ExplainAction) -> None:
        why = await self.pane("why")
        why.explain_action(message.episode, message.agent, message.step, message.action)  # type: ignore[attr-defined]
        await self.action_show("why")
