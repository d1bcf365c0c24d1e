"""The terminal UI (`tracelab tui`): runs, episodes, the trace with its board and why-trees, rules, a
read-only SQL console and live training curves. docs/tui.md lists the screens and keys."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tracelab.viewers.tui.app import TracelabApp


def load_app() -> type[TracelabApp]:
    """The app's class, as `tracelab tui` starts it: imported with the garbage collector paused, then every
    object made so far frozen (`gc.freeze()`). textual, DuckDB and the first screen's modules make ~45,000
    objects that live as long as the process; collecting them cost the first screen ~0.1 s of CPU (~80
    collections while importing, a full one while the screen is composed: issue 40). What this gives up: an
    object made before the app that later becomes cyclic garbage is never freed (none of the TUI's)."""
    from tracelab.frozen_imports import import_frozen
    return import_frozen("tracelab.viewers.tui.app").TracelabApp
