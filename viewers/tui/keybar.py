"""KeyBar: the footer line of keys. textual's Footer rebuilds a widget per key on every focus change
(~0.2 s on a loaded 2-core machine, paid on each jump or filter); this draws the active bindings as one
line of text, and a click on a key runs its action.

What fits: the keys in the order textual lists them (the focused view's own, most used first, then the
screen's and the app's), each whole or not at all. When the line is too narrow, keys are dropped from
the end of the list, `? help` last of all (it lists every key); `^p palette` stays at the right edge."""
from __future__ import annotations

from typing import NamedTuple

from rich.text import Text
from textual import events
from textual.screen import Screen
from textual.widget import Widget

from tracelab.viewers.tui.colours import PARTIAL

KEPT_ACTION = "help"       # the key dropped last: its screen lists the keys that did not fit


class Key(NamedTuple):   # not a dataclass: ~1-2 ms to make at import (the first screen's)
    text: Text            # " g goto t"
    action: str
    node: object          # the binding's namespace (the widget whose action it is)


def fitting(keys: list[Key], room: int) -> list[Key]:
    """The keys that fit in `room` cells, a space after each: dropped whole from the end of the list,
    the help key last."""
    shown = list(keys)
    while shown and sum(k.text.cell_len + 1 for k in shown) > room:
        drop = next((i for i in range(len(shown) - 1, -1, -1) if shown[i].action != KEPT_ACTION), len(shown) - 1)
        del shown[drop]
    return shown


class KeyBar(Widget):
    def __init__(self) -> None:
        super().__init__()
        self._keys: list[Key] = []
        self._spans: list[tuple[int, int, str, object]] = []   # x from, x to, action, namespace (as drawn)
        self._palette = Text(" ^p palette ", style=f"bold {PARTIAL}")

    def on_mount(self) -> None:
        self.screen.bindings_updated_signal.subscribe(self, self._changed)
        self._changed(self.screen)

    def on_unmount(self) -> None:
        self.screen.bindings_updated_signal.unsubscribe(self)

    def _changed(self, screen: Screen) -> None:
        keys, seen = [], set()
        for node, binding, enabled, _ in screen.active_bindings.values():
            if not binding.show or not enabled or binding.action in seen:
                continue
            seen.add(binding.action)
            text = Text()
            text.append(f" {self.app.get_key_display(binding)} ", style=f"bold {PARTIAL}")
            text.append(binding.description)     # plain: the key alone is marked
            keys.append(Key(text, binding.action, node))
        self._keys = keys
        self.refresh()

    def render(self) -> Text:
        room = self.size.width - self._palette.cell_len
        text, spans = Text(), []
        for key in fitting(self._keys, room):
            start = text.cell_len
            text.append_text(key.text)
            spans.append((start, text.cell_len, key.action, key.node))
            text.append(" ")
        self._spans = spans
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
