"""The screen of one open run: a tab per view (Episodes, Trace, Why, Rules, SQL, Training), the keys
1-6 to switch, and the messages that pass an episode, a rule or a change from one view to another."""
from __future__ import annotations

from pathlib import Path

from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import Screen
from textual.widgets import Footer, Static, TabbedContent, TabPane

from tracelab.viewers.tui.episodes import EpisodesPane
from tracelab.viewers.tui.messages import ExplainChange, OpenTrace
from tracelab.viewers.tui.rules import RulesPane
from tracelab.viewers.tui.source import RunSource
from tracelab.viewers.tui.sql import SqlPane
from tracelab.viewers.tui.trace import TracePane
from tracelab.viewers.tui.training import TrainingPane
from tracelab.viewers.tui.why import WhyPane

TABS = (("episodes", "1 Episodes"), ("trace", "2 Trace"), ("why", "3 Why"), ("rules", "4 Rules"),
        ("sql", "5 SQL"), ("training", "6 Training"))


class RunScreen(Screen):
    BINDINGS = [
        *(Binding(str(i + 1), f"show('{tab}')", title.split()[1], show=False) for i, (tab, title) in enumerate(TABS)),
        Binding("escape", "cancel_or_back", "cancel/back"),
    ]

    def __init__(self, path: Path) -> None:
        super().__init__()
        self.path = path
        self.source = RunSource(path)
        self.episode: int | None = None

    def compose(self) -> ComposeResult:
        kind = "live" if self.source.live else "sealed"
        yield Static(f" {self.path.name}  ({kind} · {self.path})", id="title", classes="title")
        panes = {"episodes": EpisodesPane(self.source), "trace": TracePane(self.source),
                 "why": WhyPane(self.source), "rules": RulesPane(self.source), "sql": SqlPane(self.source),
                 "training": TrainingPane(self.source)}
        with TabbedContent(initial="episodes", id="tabs"):
            for tab, title in TABS:
                with TabPane(title, id=tab):
                    yield panes[tab]
        yield Footer()

    def action_show(self, tab: str) -> None:
        self.query_one(TabbedContent).active = tab
        self.call_after_refresh(self._focus_pane, tab)

    def _focus_pane(self, tab: str) -> None:
        pane = self.query_one(f"#{tab} > *")
        focus = getattr(pane, "focus_default", None)
        if focus is not None:
            focus()

    def on_tabbed_content_tab_activated(self, event: TabbedContent.TabActivated) -> None:
        if event.pane.id:
            self.call_after_refresh(self._focus_pane, event.pane.id)

    def action_cancel_or_back(self) -> None:
        if self.source.interrupt():
            self.notify("query cancelled")
            return
        self.app.pop_screen()

    def on_unmount(self) -> None:
        self.source.close()

    # ---- passing things between views ------------------------------------------------------------------
    def on_open_trace(self, message: OpenTrace) -> None:
        self.episode = message.episode
        self.query_one(TracePane).show_episode(message.episode, rule=message.rule, at_t=message.at_t)
        self.action_show("trace")

    def on_explain_change(self, message: ExplainChange) -> None:
        self.query_one(WhyPane).explain(message.episode, message.atom, message.t)
        self.action_show("why")
