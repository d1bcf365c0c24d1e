"""Where the user was in a run, kept for the session: a run closed (Esc to the Runs screen) and opened again
opens on the view it was left on, with the Episodes' filters, sort and cursor and the trace's episode,
filters and cursor as they were. The app holds one RunPlace per open run (by its paths); nothing is
written to disk. NamedTuples, not dataclasses: a dataclass costs ~1-2 ms of CPU to make at import, and these
are imported with the first screen (issue 40)."""
from __future__ import annotations

from typing import NamedTuple


class EpisodesPlace(NamedTuple):
    outcome: str | None        # the outcome selector's value (None: all)
    kind: str | None           # the kind selector's value (None: all)
    length: str                # the length filter's text
    sort_key: str
    sort_desc: bool
    cursor: int                # the row the cursor was on (the same filter and sort give the same rows)


class TracePlace(NamedTuple):
    episode: int
    time_range: str            # the filter fields' text
    atom: str
    label: str
    rule: str
    atom_id: int | None        # `a`: only this atom
    hide_static: bool
    board: bool | None         # the user's `b`, else None (by width)
    seq: int | None            # the change the cursor was on


class RunPlace(NamedTuple):
    view: str                  # the tab it was left on
    episodes: EpisodesPlace | None
    trace: TracePlace | None   # None: no episode was opened
