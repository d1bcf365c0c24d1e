"""Text from a run (names, atoms, outcomes, its command, errors quoting them) as the TUI shows it: a
rich Text, never markup (a rule named `[@click=app.quit]` shows those characters), with its control
characters escaped (engine.terminal_text.printable: no escape sequence reaches the terminal)."""
from __future__ import annotations

from rich.text import Text

from tracelab.engine.terminal_text import has_unsafe, printable


def shown(text: str, style: str = "") -> Text:
    return Text(printable(text), style=style)


def shown_text(text: Text) -> Text:
    """A Text built elsewhere, escaped if it holds a control character (its styles are then dropped:
    a rare, hostile string)."""
    return shown(text.plain, str(text.style)) if has_unsafe(text.plain) else text
