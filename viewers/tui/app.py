"""The tracelab terminal UI: the Runs screen, and for an open run its views (run_screen.py).
Start it with `tracelab tui [RUN | DIR ...]`."""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from textual.app import App, SystemCommand
from textual.binding import Binding
from textual.screen import Screen

from tracelab.store.catalog import DEFAULT_ROOTS, is_run
from tracelab.viewers.tui.places import RunPlace
from tracelab.viewers.tui.run_screen import TABS, RunScreen
from tracelab.viewers.tui.runs_screen import RunsScreen


class TracelabApp(App[None]):
    TITLE = "tracelab"
    CSS_PATH = "tracelab.tcss"   # every view's styles
    BINDINGS = [
        Binding("question_mark", "help", "help"),
        Binding("q", "quit", "quit"),
    ]

    def __init__(self, paths: Sequence[str | Path] = ()) -> None:
        super().__init__()
        self.paths = [Path(p) for p in paths] or list(DEFAULT_ROOTS)
        # where the user left each run (by its paths), so that reopening it in this session opens there
        self.run_places: dict[tuple[Path, ...], RunPlace] = {}

    def on_mount(self) -> None:
        # opened on runs: the first, the others overlaid in Training and SQL; the Runs screen (its catalog
        # read) is made only when the user goes back to it (close_run): the first screen is the run's
        if all(is_run(p) for p in self.paths) and self.show_run(self.paths[0], self.paths[1:]):
            return
        self.push_screen(RunsScreen(self.paths))

    def close_run(self) -> None:
        """Back from an open run to the Runs screen (made now if the app opened on the run)."""
        if isinstance(self.screen, RunScreen):
            self.screen.keep_where()
        if isinstance(self.screen_stack[-2], RunsScreen):
            self.pop_screen()
        else:   # popped first, as above (the run's screen suspended and removed at once), then made
            self.pop_screen()
            self.push_screen(RunsScreen(self.paths))

    def show_run(self, path: Path, overlaid: Sequence[Path] = ()) -> bool:
        """Open a run's screen; False (with a message) if the run cannot be opened."""
        key = tuple(p.resolve() for p in (path, *overlaid))
        try:
            screen = RunScreen(path, overlaid, self.run_places.get(key),
                               lambda place: self.run_places.__setitem__(key, place))
        except Exception as e:  # noqa: BLE001 - a run that cannot be opened is a message, not a crash
            self.notify(f"cannot open {', '.join(map(str, [path, *overlaid]))}: {e}", severity="error", timeout=8)
            return False
        self.push_screen(screen)
        return True

    async def _saved_queries(self, screen: RunScreen) -> None:
        await screen.action_show("sql")
        sql = await screen.pane("sql")
        sql.action_saved()  # type: ignore[attr-defined]

    async def _eval_game(self, screen: RunScreen, direction: int) -> None:
        await screen.action_show("trace")
        trace = await screen.pane("trace")
        trace.action_eval_game(direction)  # type: ignore[attr-defined]

    def action_help(self) -> None:
        from tracelab.viewers.tui.help import HelpScreen   # textual's Markdown (markdown_it): when asked
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())

    def get_system_commands(self, screen: Screen) -> Iterable[SystemCommand]:
        yield from super().get_system_commands(screen)
        yield SystemCommand("Help", "the keys of every view", self.action_help)
        if isinstance(screen, RunScreen):
            for tab, title in TABS:
                if not screen.has_view(tab):
                    continue
                name = title.split()[1]
                yield SystemCommand(f"Show {name}", f"switch to the {name} view (key {title.split()[0]})",
                                    lambda tab=tab: screen.action_show(tab))
            yield SystemCommand("Saved queries", "pick a saved SQL query and its parameters",
                                lambda: self._saved_queries(screen))
            for direction, which in ((1, "Next"), (-1, "Previous")) if screen.source.games else ():
                yield SystemCommand(f"{which} evaluation game", f"a training run's {which.lower()} evaluation game "
                                    f"in the trace (key {']' if direction > 0 else '['})",
                                    lambda d=direction: self._eval_game(screen, d))
            yield SystemCommand("Back to runs", "close this run", self.close_run)
