"""KeyBar: the footer line of keys. textual's Footer rebuilds a widget per key on every focus change
(~0.2 s on a loaded 2-core machine, paid on each jump or filter); this draws the active bindings as one
line of text, and a click on a key runs its action."""
from __future__ import annotations

from rich.text import Text
from textual import events
from textual.screen import Screen
from textual.widget import Widget

from tracelab.viewers.tui.colours import PARTIAL


class KeyBar(Widget):
    def __init__(self) -> None:
        super().__init__()
        self._spans: list[tuple[int, int, str, object]] = []   # x from, x to, action, namespace
        self._text = Text()

    def on_mount(self) -> None:
        self.screen.bindings_updated_signal.subscribe(self, self._changed)
        self._changed(self.screen)

    def on_unmount(self) -> None:
        self.screen.bindings_updated_signal.unsubscribe(self)

    def _changed(self, screen: Screen) -> None:
        text, spans, seen = Text(), [], set()
        for node, binding, enabled, _ in screen.active_bindings.values():
            if not binding.show or not enabled or binding.action in seen:
                continue
            seen.add(binding.action)
            start = text.cell_len
            text.append(f" {self.app.get_key_display(binding)} ", style=f"bold {PARTIAL}")
            text.append(binding.description)
            spans.append((start, text.cell_len, binding.action, node))
            text.append(" ")
        palette = Text(" ^p palette ", style=f"bold {PARTIAL}")
        self._text, self._spans = text, spans
        self._palette = palette
        self.refresh()

    def render(self) -> Text:
        room = self.size.width - self._palette.cell_len
        text = self._text.copy()
        text.truncate(max(0, room))
        text.pad_right(max(0, room - text.cell_len))
        return text + self._palette

    async def on_click(self, event: events.Click) -> None:
        if event.x >= self.size.width - self._palette.cell_len:
            self.app.action_command_palette()
            return
        for start, end, action, node in self._spans:
            if start <= event.x < end:
                await self.app.run_action(action, node)  # type: ignore[arg-type]
                return
