"""Golden-file snapshots of the TUI's screens as normalised text (pytest-textual-snapshot pins pytest < 9).

A snapshot is the screen's characters line by line, then each line's cell styles run-length encoded as
short tokens (a hash of "fg on bg attrs", so one colour change touches only the lines that use it), then
a legend of the tokens. What varies between runs or machines (start times, sizes on disk, run status,
live/sealed, the numba compile notice) is masked cell by cell before anything is compared.
Update the golden files after an intended change: TRACELAB_UPDATE_SNAPSHOTS=1 (docs/tui.md, Tests)."""
from __future__ import annotations

import difflib
import hashlib
import io
import os
import re
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.segment import Segment
from rich.style import Style

SNAPSHOT_DIR = Path(__file__).resolve().parent / "data" / "tui_snapshots"
UPDATE = os.environ.get("TRACELAB_UPDATE_SNAPSHOTS") == "1"
MASK_CHAR = "▒"

# spans of a line that vary between runs or machines; each is replaced cell for cell by MASK_CHAR
MASKS = [
    re.compile(r"\d{4}-\d\d-\d\d[ T]\d\d:\d\d:\d\d"),              # start times, clocks
    re.compile(r"\b\d+(?:\.\d)? (?:B|KB|MB|GB)\b"),                 # sizes on disk
    re.compile(r"\b(?:running|finished|interrupted|crashed)\b"),   # a run's status, from the writer's lock
    re.compile(r"\b(?:live|sealed)\b"),                            # whether the run is still being written
    re.compile(r"compiling the engine[^│]*"),                      # numba's first-run notice
]


def _plain(style: Style | None) -> str:
    """A cell's look without textual's per-widget meta (ids, click handlers)."""
    if style is None:
        return ""
    return str(Style(color=style.color, bgcolor=style.bgcolor, bold=style.bold, dim=style.dim,
                     italic=style.italic, underline=style.underline, reverse=style.reverse,
                     strike=style.strike))


def _token(style: str) -> str:
    return hashlib.sha1(style.encode()).hexdigest()[:3]


def screen_cells(app: Any) -> list[list[tuple[str, str]]]:
    """The current screen as rows of (character, style) cells, the way export_screenshot draws it."""
    width, height = app.size
    console = Console(width=width, height=height, file=io.StringIO(), force_terminal=True,
                      color_system="truecolor", legacy_windows=False, safe_box=False)
    update = app.screen._compositor.render_update(full=True, screen_stack=app._background_screens)
    rows = []
    for line in Segment.split_lines(console.render(update)):
        cells = []
        for seg in line:
            if seg.control:
                continue
            look = _plain(seg.style)
            cells.extend((ch, look) for ch in seg.text)
        rows.append(cells)
    return rows[:height]


def mask(rows: list[list[tuple[str, str]]]) -> list[list[tuple[str, str]]]:
    masked = []
    for cells in rows:
        text = "".join(ch for ch, _ in cells)
        cells = list(cells)
        for pattern in MASKS:
            for m in pattern.finditer(text):
                for i in range(m.start(), m.end()):
                    cells[i] = (MASK_CHAR, "masked")
        masked.append(cells)
    return masked


def render_snapshot(rows: list[list[tuple[str, str]]]) -> str:
    rows = mask(rows)
    text = ["".join(ch for ch, _ in cells).rstrip() for cells in rows]
    styles, legend = [], {}
    for n, cells in enumerate(rows):
        runs: list[list[Any]] = []
        for _, look in cells:
            token = _token(look)
            legend[token] = look
            if runs and runs[-1][0] == token:
                runs[-1][1] += 1
            else:
                runs.append([token, 1])
        styles.append(f"{n:2d} " + " ".join(f"{t}*{k}" for t, k in runs))
    return "\n".join(["# text", *text, "# styles (token*cells)", *styles, "# legend",
                      *(f"{t} {legend[t] or 'default'}" for t in sorted(legend))]) + "\n"


def check_snapshot(name: str, app: Any) -> str | None:
    """Compare the app's screen with tests/data/tui_snapshots/NAME.txt; None if equal, else a unified diff.
    With TRACELAB_UPDATE_SNAPSHOTS=1 the golden file is (re)written instead."""
    got = render_snapshot(screen_cells(app))
    path = SNAPSHOT_DIR / f"{name}.txt"
    if UPDATE or not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(got, encoding="utf-8")
        return None if UPDATE else f"{path} did not exist; written now: look at it and commit it"
    want = path.read_text(encoding="utf-8")
    if got == want:
        return None
    return "".join(difflib.unified_diff(want.splitlines(keepends=True), got.splitlines(keepends=True),
                                        f"golden {path.name}", "screen now", n=1))
