"""The colours every view shares: the teams (red / blue) and the four kinds of truth value
([1,1] true, [0,0] false, [0,1] unknown, anything else a partial bound)."""
from __future__ import annotations

from rich.text import Text
from tracelab.viewers.tui.shown_text import shown

RED_TEAM = "#ff5f5f"
BLUE_TEAM = "#5fafff"
TRUE = "#5fd75f"
FALSE = "#d7875f"
UNKNOWN = "#8a8a8a"
PARTIAL = "#d7d75f"
DIM = "#6c6c6c"


def bound_text(lower: float | None, upper: float | None) -> str:
    if lower is None or upper is None:
        return "?"
    return f"[{lower:g},{upper:g}]"


def bound_colour(lower: float | None, upper: float | None) -> str:
    """The colour of a truth value: [1,1], [0,0], [0,1], or other."""
    if (lower, upper) == (1, 1):
        return TRUE
    if (lower, upper) == (0, 0):
        return FALSE
    if (lower, upper) == (0, 1):
        return UNKNOWN
    return PARTIAL


def styled_bound(lower: float | None, upper: float | None) -> Text:
    return Text(bound_text(lower, upper), style=bound_colour(lower, upper))


def team_colour(name: str | None) -> str | None:
    """Red or blue for names of a team's things (red-agent-1, blue-bullet-1-1, red, blue_base)."""
    if not name:
        return None
    if name.startswith("red") or "(red" in name or ",red" in name:
        return RED_TEAM
    if name.startswith("blue") or "(blue" in name or ",blue" in name:
        return BLUE_TEAM
    return None


def styled_name(name: str | None) -> Text:
    colour = team_colour(name)
    return shown(name or "", colour or "")
